"""No function in jaxexo/ or the benchmark modules (benchmarks/benchlib) over MAX_LINES lines, so that
each reads as one concern: every function, method and nested function, from its ``def`` line
(decorators not counted) to its last line, docstring included. A long one splits at its seams (its setup, its measurement, its report)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 100


def long_functions(package: Path = ROOT / "jaxexo", limit: int = MAX_LINES) -> list[str]:
    """``file:line name (N lines)`` of each function in the package's modules longer than ``limit``."""
    found = []
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > limit:
                    found.append(
                        f"{path.relative_to(package.parent)}:{node.lineno} {node.name} ({lines} lines)"
                    )
    return found


def test_no_function_is_over_100_lines():
    long = long_functions() + long_functions(ROOT / "benchmarks" / "benchlib")
    assert not long, f"functions over {MAX_LINES} lines:\n" + "\n".join(long)


def test_the_count_finds_a_long_nested_function(tmp_path):
    body = "\n".join(f"            x{i} = {i}" for i in range(MAX_LINES))
    (tmp_path / "m.py").write_text(
        f"def short():\n    pass\n\n\nclass A:\n    def outer(self):\n        def inner():\n{body}\n"
    )
    found = long_functions(tmp_path)
    assert [f.split(" ", 1)[1] for f in found] == [
        f"outer ({MAX_LINES + 2} lines)",
        f"inner ({MAX_LINES + 1} lines)",
    ]
