"""No dead functions: every function and method defined in the package and the benchmark modules
(benchmarks/benchlib), and every helper a test module defines, is named somewhere else, in the package,
the benchmarks, a test or pyproject.toml (the CLI entry point), read from the source with ``ast``.

A name counts as a reference where it is loaded (``f``), an attribute (``x.f``), an imported name, or a
word inside a string that is not a docstring (``getattr(obj, "f")``, the entry point
``"jaxexo.cli:main"``); a function's references inside its own body (recursion) do not count. The scan
matches names, not bindings, so a function stays alive while any other function of its name is used:
it finds code nothing names, which is how dead code usually looks. Special methods (``__x__``) are
called by Python itself; test functions and fixtures by pytest.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from conftest import ROOT

WORD = re.compile(r"[A-Za-z_]\w*")
FUNCS = (ast.FunctionDef, ast.AsyncFunctionDef)

# Functions the scan calls dead that are alive by a route it cannot see ("path:qualified name": why).
# Empty today; an entry that no longer matches a dead function fails the test, so it can only shrink.
ALLOWED: dict[str, str] = {}


def _is_pytest_hook(node, in_test: bool) -> bool:
    """Test functions, test classes' methods, fixtures and conftest hooks (``pytest_configure``...):
    pytest calls them by their names."""
    return in_test and (
        node.name.startswith(("test", "pytest_"))
        or any("fixture" in ast.unparse(d) for d in node.decorator_list)
    )


def definitions(path: Path, tree: ast.Module, in_test: bool):
    """(qualified name, node) of the module's functions and its classes' methods."""
    for node in tree.body:
        if isinstance(node, FUNCS) and not _is_pytest_hook(node, in_test):
            yield node.name, node
        elif isinstance(node, ast.ClassDef) and not (in_test and node.name.startswith("Test")):
            for sub in node.body:
                if isinstance(sub, FUNCS) and not _is_pytest_hook(sub, in_test):
                    yield f"{node.name}.{sub.name}", sub


def references(tree: ast.Module):
    """(name, line) of every place the module names something."""
    docstrings = {
        id(n.body[0].value)
        for n in ast.walk(tree)
        if isinstance(n, (ast.Module, ast.ClassDef, *FUNCS))
        and n.body
        and isinstance(n.body[0], ast.Expr)
        and isinstance(n.body[0].value, ast.Constant)
    }
    for n in ast.walk(tree):
        if isinstance(n, ast.Name):
            yield n.id, n.lineno
        elif isinstance(n, ast.Attribute):
            yield n.attr, n.lineno
        elif isinstance(n, ast.alias):
            yield n.name.rpartition(".")[2], 0
        elif isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings:
            for w in WORD.findall(n.value):
                yield w, n.lineno


def dead_functions(
    checked: list[Path], users: list[Path], extra_text: str = "", tests: tuple[Path, ...] = ()
):
    """(path, line, qualified name) of each function defined in ``checked`` that nothing in ``checked``,
    ``users`` or ``extra_text`` names outside its own body."""
    refs: dict[str, list[tuple[Path | None, int]]] = {}
    defs = []
    for p in dict.fromkeys(checked + users):
        tree = ast.parse(p.read_text(), filename=str(p))
        if p in checked:
            defs += [(p, q, node) for q, node in definitions(p, tree, in_test=p in tests)]
        for name, line in references(tree):
            refs.setdefault(name, []).append((p, line))
    for w in WORD.findall(extra_text):
        refs.setdefault(w, []).append((None, 0))
    dead = []
    for p, qual, node in defs:
        name = qual.rpartition(".")[2]
        if name.startswith("__") and name.endswith("__"):
            continue
        if not any(
            f != p or not node.lineno <= line <= node.end_lineno for f, line in refs.get(name, ())
        ):
            dead.append((p, node.lineno, qual))
    return dead


def test_every_function_is_reached():
    package = sorted((ROOT / "jaxexo").rglob("*.py"))
    package += sorted((ROOT / "benchmarks" / "benchlib").rglob("*.py"))  # the benchmark modules
    tests = sorted((ROOT / "tests").rglob("*.py"))
    scripts = sorted((ROOT / "benchmarks").glob("*.py"))
    dead = {
        f"{p.relative_to(ROOT).as_posix()}:{qual}": line
        for p, line, qual in dead_functions(
            package + tests, scripts, (ROOT / "pyproject.toml").read_text(), tuple(tests)
        )
    }
    unexplained = [f"{k} (line {line})" for k, line in dead.items() if k not in ALLOWED]
    assert not unexplained, (
        "functions nothing calls (delete them, or explain them in ALLOWED):\n"
        + "\n".join(unexplained)
    )
    assert not set(ALLOWED) - set(dead), (
        f"ALLOWED entries that are no longer dead: {sorted(set(ALLOWED) - set(dead))}"
    )


def test_the_scan_finds_planted_dead_code(tmp_path):
    """An independent reference: a hand-written module whose dead and live functions are known."""
    mod = tmp_path / "mod.py"
    mod.write_text('''"""Docstring naming unused_in_doc, which must not keep it alive."""
import os


def used_by_call():
    return 1


def recursive_only(n):
    return recursive_only(n - 1) if n else 0


def unused_in_doc():
    pass


def by_string():
    pass


class Thing:
    def __init__(self):
        self.x = used_by_call()

    def method_used(self):
        return getattr(self, "by_string")

    def method_dead(self):
        pass


def main():
    Thing().method_used()
''')
    test = tmp_path / "test_mod.py"
    test.write_text("""import pytest


@pytest.fixture
def fix():
    return 1


def helper_dead():
    pass


def test_it(fix):
    pass
""")
    dead = dead_functions([mod, test], [], extra_text='mod = "mod:main"', tests=(test,))
    assert sorted(q for _, _, q in dead) == [
        "Thing.method_dead",
        "helper_dead",
        "recursive_only",
        "unused_in_doc",
    ]
    # without the entry point, main is dead too
    assert "main" in {q for _, _, q in dead_functions([mod], [])}
