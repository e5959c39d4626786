"""What travels between modules is a typed record (docs/architecture.md, "Records"), read from the
source with ``ast``: no function in jaxexo/ or the benchmark modules (benchmarks/benchlib) returns a
dict of five keys or more or a tuple of more than four, except the JSON documents, table rows and
contracts listed in ALLOWED with their reason.
An entry that no longer returns such a value must leave the list."""

from __future__ import annotations

import ast

from conftest import ROOT

MAX_KEYS, MAX_ITEMS = 4, 4

JSON = "a JSON document: written to a file as it is built"
ROW = "one Markdown table row's cells"
# (path under jaxexo/, or benchmarks/benchlib/... for the benchmark modules, function): why it may
# return a wide dict or tuple.
ALLOWED = {
    ("benchmarks/benchlib/course_bench.py", "independent_checks"): JSON,
    ("benchmarks/benchlib/device_ready_bench.py", "_per_swing"): JSON,
    ("benchmarks/benchlib/device_ready_bench.py", "_duration_cells"): ROW,
    ("benchmarks/benchlib/course_bench.py", "summarize"): JSON,
    ("benchmarks/benchlib/generate_bench.py", "set_figures"): JSON,
    ("benchmarks/benchlib/model_study_bench.py", "verdicts"): JSON,
    ("benchmarks/benchlib/population_bench.py", "population_row"): JSON,
    ("benchmarks/benchlib/safety_bench.py", "generator_figures"): JSON,
    ("config/obstacles.py", "write_terrain"): "the terrain table as TOML",
    ("benchmarks/benchlib/obstacle_change_bench.py", "_rates"): JSON,
    ("benchmarks/benchlib/generate_bench.py", "smoothing_counts"): JSON,
    ("benchmarks/benchlib/thesis_baseline.py", "train"): JSON + " (the baseline's figures)",
    ("course/record.py", "to_dict"): JSON,
    ("evaluation/metrics.py", "summarize"): JSON + " (an eval report's entry)",
    ("evaluation/metrics.py", "summarize_device"): JSON + " (an eval report's entry)",
    ("evaluation/reproduce.py", "population_summary"): JSON,
    ("swing/export.py", "scene_dict"): JSON,
    ("swing/export.py", "units"): JSON,
    ("swing/export.py", "timed_dict"): JSON,
    ("swing/limits.py", "to_dict"): JSON,
    ("sim/report.py", "to_dict"): JSON + " (a replay report's entry)",
    ("sweep/report.py", "write_report"): JSON + " (the sweep's summary)",
    ("swing/trajectory.py", "to_dict"): JSON,
    ("train/evaluate.py", "summarize"): JSON + " (eval.json)",
    ("train/metrics_log.py", "chunk_row"): JSON + " (a metrics.jsonl line)",
    ("benchmarks/benchlib/landing_bench.py", "_cells"): ROW,
    ("benchmarks/benchlib/population_bench.py", "_cost_cells"): ROW,
    ("benchmarks/benchlib/replay_bench.py", "_driven"): ROW,
    ("benchmarks/benchlib/safety_bench.py", "_cells"): ROW,
    ("benchmarks/benchlib/timing_bench.py", "_cells"): ROW,
    ("benchmarks/benchlib/tracking_bench.py", "_cells"): ROW,
    ("benchmarks/benchlib/train_steady_bench.py", "_steady_cells"): ROW,
    ("train/records.py", "report"): JSON + " (eval.json's last fields)",
    ("train/records.py", "row"): JSON + " (a metrics.jsonl line)",
    ("env/exo_step.py", "step_env"): "the gymnax step: (obs, state, reward, done, info)",
    (
        "benchmarks/benchlib/thesis_baseline.py",
        "step",
    ): "the gym step: (obs, reward, terminated, truncated, info)",
    ("plots/animate.py", "draw"): "matplotlib's blitted artists",
    ("plots/animate.py", "animate_swing"): "matplotlib's blitted artists (draw, nested)",
    (
        "shield/scalar.py",
        "_leg",
    ): "one leg's floats on the generator's per-step path, inside its module",
}


def _width(node: ast.expr) -> tuple[str, int] | None:
    """('dict', keys) or ('tuple', items) of a returned literal (``{...}``, ``dict(k=...)``, ``(...)``)."""
    if isinstance(node, ast.Dict):
        return "dict", len(node.keys)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict":
        if not node.args:
            return "dict", len(node.keywords)
    if isinstance(node, ast.Tuple):
        return "tuple", len(node.elts)
    return None


def _wide_returns() -> dict[tuple[str, str], str]:
    found = {}
    pkg = ROOT / "jaxexo"
    for path in sorted(pkg.rglob("*.py")) + sorted(
        (ROOT / "benchmarks" / "benchlib").rglob("*.py")
    ):
        rel = path.relative_to(pkg if path.is_relative_to(pkg) else ROOT).as_posix()
        for fn in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Return) and node.value is not None:
                    w = _width(node.value)
                    if w and w[1] > (MAX_KEYS if w[0] == "dict" else MAX_ITEMS):
                        found[(rel, fn.name)] = (
                            f"{rel}:{node.lineno} {fn.name} returns a {w[0]} of {w[1]}"
                        )
    return found


def test_no_wide_dict_or_tuple_travels_between_modules():
    found = _wide_returns()
    new = sorted(v for k, v in found.items() if k not in ALLOWED)
    assert not new, "return a frozen typed record instead:\n" + "\n".join(new)
    stale = sorted(set(ALLOWED) - set(found))
    assert not stale, f"no longer wide, remove from ALLOWED: {stale}"


def test_the_scan_finds_a_wide_return(tmp_path):
    """The scan itself: literal dicts, dict(...) calls and tuples over the limit, not those within it."""
    src = (
        "def a():\n    return {'a': 1, 'b': 2, 'c': 3, 'd': 4, 'e': 5, 'f': 6}\n"
        "def b():\n    return dict(a=1, b=2, c=3, d=4, e=5, f=6)\n"
        "def c():\n    return 1, 2, 3, 4, 5\n"
        "def d():\n    return {'a': 1, 'b': 2, 'c': 3, 'd': 4, 'e': 5}\n"
        "def e():\n    return 1, 2, 3, 4\n"
    )
    widths = {}
    for fn in ast.parse(src).body:
        r = fn.body[0].value
        widths[fn.name] = _width(r)
    assert widths == {
        "a": ("dict", 6),
        "b": ("dict", 6),
        "c": ("tuple", 5),
        "d": ("dict", 5),
        "e": ("tuple", 4),
    }
