"""The package's layers, read from the source with ``ast`` (every import, function-local ones too).

jaxexo is built in floors: the physics (written once for NumPy, JAX and plain floats) at the bottom,
the configuration that turns a TOML file into its parameters above it, then the environment, the
generators and training, and the tools that compare, sweep and report on top. A module may import
from its own floor's package or from a lower floor, never from a higher one or sideways from another
package on its floor; no two modules import each other, directly or round a longer circle; and no
module reaches into another package's private names (``_x``), by import or as ``module._x``.
"""

from __future__ import annotations

import ast
from pathlib import Path

from conftest import ROOT

# Lowest first. A module belongs to the longest prefix that names it; "jaxexo" alone is the package's
# face (jaxexo/__init__.py), at the top like the command line.
LAYERS = (
    ("jaxexo.physics",),
    ("jaxexo.shield",),  # the shield's rule and its forms: under the environment that masks with it
    ("jaxexo.config",),
    ("jaxexo.storage",),  # also the policy file read and checked for the generators (policy_check)
    ("jaxexo.env",),
    (
        "jaxexo.swing",
    ),  # what every generator does with its path: smooth, clear, check, time, export
    ("jaxexo.baselines",),  # CFFTG, also the RL generator's fallback planner
    ("jaxexo.inference",),  # the RL generator and the public face of generation
    ("jaxexo.course", "jaxexo.plots", "jaxexo.summary"),  # walks, figures, summaries
    (
        "jaxexo.train",
    ),  # exports policies for the generator, and picks them as it swings (selection)
    ("jaxexo.sim",),
    ("jaxexo.sweep", "jaxexo.evaluation"),
    ("jaxexo.cli", "jaxexo"),
)

# The one allow-list: imports (importer, module) and private names (importer, module._name) that break
# the rules today. Remove an entry when its use is gone; the test fails on an entry that no longer
# matches anything, so this list can only shrink.
KNOWN_EXCEPTIONS: set = set()

# Scripts and the benchmark modules outside the package: any import, but no private names.
SCRIPT_DIRS = ("benchmarks",)


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted((ROOT / "jaxexo").rglob("*.py"))}


MODULES = _modules()


def _resolve(importer: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` names (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    base = importer.split(".")
    is_pkg = MODULES.get(importer, Path()).name == "__init__.py"
    base = base[: len(base) - node.level + (1 if is_pkg else 0)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(name: str, path: Path):
    """(imported module, private names taken from it, line) for every jaxexo import of a file, and the
    local names bound to jaxexo modules (for ``module._x``)."""
    tree = ast.parse(path.read_text(), str(path))
    out, bound = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "jaxexo":
                    out.append((a.name, [], node.lineno))
                    bound[a.asname or a.name] = a.name
        elif isinstance(node, ast.ImportFrom):
            mod = _resolve(name, node)
            if mod.split(".")[0] != "jaxexo":
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                if sub in MODULES:  # a submodule: the import is of that module
                    out.append((sub, [], node.lineno))
                    bound[a.asname or a.name] = sub
                else:
                    out.append((mod, [a.name] if _private(a.name) else [], node.lineno))
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            root = _dotted(node.value)
            if root in bound:
                out.append((bound[root], [node.attr], node.lineno))
    return out


def _dotted(node) -> str | None:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        head = _dotted(node.value)
        return None if head is None else f"{head}.{node.attr}"
    return None


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _package(module: str) -> str:
    """The package a module belongs to for the private-name rule: jaxexo.<package>."""
    return ".".join(module.split(".")[:2])


def _floor(module: str) -> tuple[int, str]:
    best = None
    for level, prefixes in enumerate(LAYERS):
        for prefix in prefixes:
            if module == prefix or (prefix != "jaxexo" and module.startswith(prefix + ".")):
                if best is None or len(prefix) > len(best[1]):
                    best = (level, prefix)
    assert best is not None, f"{module} is on no floor of LAYERS: add it"
    return best


def _edges():
    """{(importer, imported): first line} over the package, without KNOWN_EXCEPTIONS."""
    edges = {}
    for name, path in MODULES.items():
        for target, _, line in _imports(name, path):
            if target != name and (name, target) not in KNOWN_EXCEPTIONS:
                edges.setdefault((name, target), line)
    return edges


def test_every_module_is_on_a_floor():
    for name in MODULES:
        _floor(name)


def test_no_import_goes_up_or_sideways():
    bad = []
    for (a, b), line in sorted(_edges().items()):
        la, lb = _floor(a)[0], _floor(b)[0]
        if la < lb or (la == lb and _package(a) != _package(b)):
            bad.append(
                f"{MODULES[a].relative_to(ROOT)}:{line}: {a} (floor {la}) imports {b} (floor {lb})"
            )
    assert not bad, "imports against the layer map:\n" + "\n".join(bad)


def test_no_import_cycles():
    graph: dict[str, set[str]] = {}
    for a, b in _edges():
        graph.setdefault(a, set()).add(b)
    cycles, state = [], {}

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt) :] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_no_private_names_across_packages():
    files = [(n, p) for n, p in MODULES.items()]
    files += [(f"{d}.{p.stem}", p) for d in SCRIPT_DIRS for p in sorted((ROOT / d).rglob("*.py"))]
    bad = []
    for name, path in files:
        for target, private, line in _imports(name, path):
            private = [x for x in private if (name, f"{target}.{x}") not in KNOWN_EXCEPTIONS]
            if private and _package(target) != _package(name):
                bad.append(
                    f"{path.relative_to(ROOT)}:{line}: {name} uses {target}.{', '.join(private)}"
                )
    assert not bad, "private names used across packages:\n" + "\n".join(bad)


def test_known_exceptions_still_exist():
    """An exception whose import is gone is removed from KNOWN_EXCEPTIONS, so the list only shrinks."""
    found = {(n, t) for n, p in MODULES.items() for t, _, _ in _imports(n, p)}
    found |= {
        (n, f"{t}.{x}")
        for n, p in MODULES.items()
        for t, private, _ in _imports(n, p)
        for x in private
    }
    stale = sorted(KNOWN_EXCEPTIONS - found)
    assert not stale, f"remove these from KNOWN_EXCEPTIONS, their imports are gone: {stale}"


def test_the_package_imports_neither_tests_nor_benchmarks():
    """What a user imports is the package alone: no module of it imports a test module or a benchmark
    one, but the benchmark commands (jaxexo.cli.bench), which run a source checkout's suite."""
    outside = {p.stem for d in ("tests", "benchmarks") for p in (ROOT / d).glob("*.py")}
    outside.add("benchlib")
    bad = []
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and not node.level:
                targets = [node.module or ""]
            else:
                continue
            for t in targets:
                suite = name == "jaxexo.cli.bench" and t.startswith("benchlib.")
                if t.split(".")[0] in outside and not suite:
                    bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: {name} imports {t}")
    assert not bad, "the package imports from outside it:\n" + "\n".join(bad)
