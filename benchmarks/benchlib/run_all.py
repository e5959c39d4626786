"""``jaxexo bench``: every benchmark in one run (parts env, train, generate, compare, baseline, course;
``skip`` any), each writing its own result files, then the summary table (summary_<date>_<machine>.md,
shown in the README) built from the figures the parts return. The parts: docs/benchmarks.md."""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable
from pathlib import Path

PARTS = ("env", "train", "generate", "compare", "baseline", "course")
ROOT = Path(__file__).resolve().parent.parent.parent


def _env_rows(env: dict) -> list[tuple[str, str, str]]:
    return [
        (
            f"environment ({layout}), 4096 envs, env-steps/s",
            f"{r['env_steps_per_s'] / 1e6:.2f} M",
            ">= 5 M" if layout == "default" else "",
        )
        for layout, results in env.items()
        for r in results
        if r["num_envs"] == 4096
    ]


def _train_rows(train: dict) -> list[tuple[str, str, str]]:
    rows = [
        (
            "trainer, thesis network, 4096 envs, env-steps/s",
            f"{r['env_steps_per_s'] / 1e6:.2f} M",
            ">= 1 M",
        )
        for r in train["throughput"]
        if r["trace"] == "forward" and r.get("num_minibatches") == 4
    ]
    rows += [
        (
            f"`jaxexo train {Path(name).name}`: wall s, strict success (raw moves)",
            f"{r['train_seconds']:.1f} s, {r.get('success_raw', r.get('success')):.3f}",
            "<= 60 s, >= 0.99" if name.endswith("default.toml") else "< 30 s",
        )
        for name, r in train["runs"].items()
    ]
    return rows


def _generate_rows(g: dict) -> list[tuple[str, str, str]]:
    bt = g["batch_ms"]
    return [
        (
            "RL generator (shielded), one swing, median (CFFTG side by side), held-out scenes",
            f"{g['single_ms']['rl']['median']:.3f} ms (CFFTG {g['single_ms']['cfftg']['median']:.3f} ms)",
            "<= 1.0 ms and <= 1.5x CFFTG (thesis ~3 ms)",
        ),
        (
            "RL generator, batch of 1000 (default / single-threaded BLAS)",
            f"{bt['default_threads']['rl'] * 1000 / g['n']:.1f} / {bt['single_thread_blas']['rl'] * 1000 / g['n']:.1f} ms",
            "<= CFFTG's and <= 150 ms (thesis 1764 ms)",
        ),
        ("`import jaxexo.inference`, cold", f"{g['import_s']['median']:.3f} s", "<= 0.3 s"),
    ]


def _compare_rows(compare: dict) -> list[tuple[str, str, str]]:
    rows = []
    for name, r in compare.items():
        what = f"{name} on {r['n']} test scenarios: success / accuracy / median ms / batch 1000 ms"
        target = (
            "RL success >= CFFTG's, median <= CFFTG's" if name == "rl" else "thesis CFFTG ~2 ms"
        )
        rows.append(
            (
                what,
                f"{r['success']:.3f} / {r['accuracy']:.3f} / {r['time_ms_median']:.3f} / {r['batch_1000_ms']:.1f}",
                target,
            )
        )
    return rows


def _baseline_rows(baseline: dict) -> list[tuple[str, str, str]]:
    t = baseline["throughput"]
    rows = [
        (
            "trainer vs thesis-style PyTorch trainer, env-steps/s",
            f"{t['jaxexo']['env_steps_per_s']:,.0f} vs {t['baseline']['env_steps_per_s']:,.0f} "
            f"= {t['ratio']:,.0f}x",
            ">= 1000x",
        )
    ]
    for e in baseline["time_to_success"]["reach"].values():
        if e.get("speedup"):
            how = " (baseline extrapolated)" if e["baseline_extrapolated"] else ""
            x = e["speedup"]
            rows.append(
                (
                    f"time to validation success {e['target']:.2f}: jaxexo vs baseline",
                    f"{e['jaxexo_s']:.1f} s vs {e['baseline_s']:,.0f} s = "
                    f"{f'{x:,.0f}' if x >= 10 else f'{x:.1f}'}x{how}",
                    "",
                )
            )
    return rows


def _course_rows(c: dict) -> list[tuple[str, str, str]]:
    r = c["duration_ratio_rl_over_cfftg"]["median"]
    x = c["per_step_over_one_swing_median"]
    return [
        (
            f"walks over {c['planned']} courses ({c['courses_drawn']} drawn, {c['refused']} refused): every "
            "swing safe, RL alone / CFFTG",
            f"{100 * c['rl_alone_success']:.1f} % / {100 * c['cfftg_success']:.1f} %",
            "RL >= 99 %",
        ),
        (
            "walk duration at the device limits, RL / CFFTG, median over courses",
            "-" if r is None else f"{r:.3f}",
            "<= 1",
        ),
        (
            "walk planning time per step / one swing's (CPU time)",
            "-" if x is None else f"{x:.2f}x",
            "<= 1.5x",
        ),
    ]


# Each part's summary rows, in the summary's order.
_PART_ROWS = (
    ("env", _env_rows),
    ("train", _train_rows),
    ("generate", _generate_rows),
    ("compare", _compare_rows),
    ("baseline", _baseline_rows),
    ("course", _course_rows),
)


def summary_rows(res: dict) -> list[tuple[str, str, str]]:
    """(figure, measured, target or thesis) rows from the parts' results."""
    return [row for part, rows in _PART_ROWS if part in res for row in rows(res[part])]


def latest_result(out_dir: Path, name: str):
    """(figures, path) of the newest ``<name>_<date>_<machine>.json`` in out_dir, or None."""
    import json

    paths = sorted(Path(out_dir).glob(f"{name}_*.json"), key=lambda p: p.stat().st_mtime)
    if not paths:
        return None
    doc = json.loads(paths[-1].read_text())
    doc.pop("machine", None)
    doc.pop("date", None)
    return (doc["results"] if name == "env" else doc), paths[-1]


@dataclasses.dataclass(frozen=True)
class BenchRun:
    """What every part of one ``jaxexo bench`` run shares: where the results go, the parts skipped,
    the sizes and the progress callback."""

    out_dir: Path
    skipped: frozenset
    n: int
    batch_size: int
    courses: int
    baseline_seconds: float
    progress: Callable
    default: Path = ROOT / "configs" / "default.toml"

    def runs(self, part: str) -> bool:
        return part not in self.skipped


def parse_skip(skip: str) -> frozenset:
    """The parts named in ``skip`` (comma-separated); ValueError for an unknown one."""
    skipped = frozenset(s.strip() for s in skip.split(",") if s.strip())
    unknown = skipped - set(PARTS)
    if unknown:
        raise ValueError(f"--skip: unknown part {sorted(unknown)[0]!r} (parts: {', '.join(PARTS)})")
    return skipped


def _env_part(b: BenchRun) -> dict:
    from jaxexo.config import load_config

    from benchlib.env_bench import run_env_benchmark

    return run_env_benchmark(load_config(b.default), "default", [1, 256, 4096, 16384], b.out_dir)


def _train_part(b: BenchRun) -> dict:
    from benchlib.train_bench import run_train_benchmark

    thesis = [
        str(ROOT / "configs" / "thesis" / f"{n}.toml")
        for n in ("a", "b", "c", "1", "2", "3", "final")
    ]
    return run_train_benchmark(b.out_dir, str(b.default), thesis, b.progress)


def _compare_part(b: BenchRun, policy, tmp: Path) -> dict:
    import json

    from jaxexo.evaluation.compare import run_eval
    from jaxexo.evaluation.machine import write_result
    from jaxexo.evaluation.report import markdown

    report = run_eval(
        policy, tmp / "eval", "cfftg", "test", b.n, figures=False, batch_size=b.batch_size
    )
    write_result(
        "compare",
        json.loads(json.dumps(report)),
        markdown(report, f"RL generator vs CFFTG, {b.n} test scenarios", []),
        b.out_dir,
    )
    return report


def _policy_parts(b: BenchRun, policy) -> dict:
    """The parts that swing a policy (generate, compare, course), in one temporary directory that
    lives until the last of them has run: ``policy``, or configs/default.toml trained into it."""
    res: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        if policy is None and ({"generate", "compare", "course"} - b.skipped):
            from jaxexo.config import load_config
            from jaxexo.train.driver import run_training

            b.progress("training configs/default.toml for the generator benchmarks")
            run_training(load_config(b.default), Path(tmp) / "run", progress=False)
            policy = Path(tmp) / "run" / "policy.npz"
        if b.runs("generate"):
            from benchlib.generate_bench import run_generate_benchmark

            res["generate"] = run_generate_benchmark(policy, b.out_dir, b.n, b.progress)
        if b.runs("compare"):
            res["compare"] = _compare_part(b, policy, Path(tmp))
        if b.runs("course"):
            from benchlib.course_bench import run_course_benchmark

            res["course"] = run_course_benchmark(policy, b.out_dir, b.courses, progress=b.progress)
    return res


def _baseline_part(b: BenchRun, notes: list[str]) -> dict | None:
    """The baseline part's figures, or None with a note when PyTorch is not installed."""
    try:
        import torch  # noqa: F401
    except ImportError:
        notes.append('baseline skipped: PyTorch is not installed (pip install -e ".[train,bench]")')
        return None
    from benchlib.baseline_bench import run_baseline_benchmark

    return run_baseline_benchmark(
        b.out_dir, str(b.default), baseline_seconds=b.baseline_seconds, progress=b.progress
    )


def write_summary(res: dict, notes: list[str], out_dir: Path, progress) -> None:
    """The summary table of the parts' figures and the notes, written to out_dir and shown."""
    from jaxexo.evaluation.machine import write_result
    from jaxexo.summary import table

    lines = [
        "# jaxexo benchmark summary",
        "",
        *table(("figure", "measured", "target / thesis"), summary_rows(res), "lll"),
    ]
    lines += [""] + [f"- {n}" for n in notes]
    md = "\n".join(lines)
    write_result("summary", {"rows": summary_rows(res), "notes": notes}, md, out_dir)
    progress(md)


def run_all(
    out_dir=None,
    policy=None,
    baseline_seconds: float = 600.0,
    skip: str = "",
    n: int = 1000,
    batch_size: int = 1000,
    progress=print,
    courses: int = 200,
) -> dict:
    """Run the parts not in ``skip`` (comma-separated), write their results and the summary to
    ``out_dir``; ``n`` scenarios for the generator parts, ``batch_size`` for the compare part's batch,
    ``courses`` drawn courses for the course part."""
    b = BenchRun(
        Path(out_dir or ROOT / "benchmarks" / "results"),
        parse_skip(skip),
        n,
        batch_size,
        courses,
        baseline_seconds,
        progress,
    )
    res: dict = {}
    notes: list[str] = []
    if b.runs("env"):
        res["env"] = _env_part(b)
    if b.runs("train"):
        res["train"] = _train_part(b)
    res.update(_policy_parts(b, policy))
    if b.runs("baseline"):
        baseline = _baseline_part(b, notes)
        if baseline is not None:
            res["baseline"] = baseline
    # Parts skipped this time: their latest results in out_dir, if any, so the summary stays whole.
    for part in PARTS:
        if part not in res:
            found = latest_result(b.out_dir, part)
            if found is not None:
                res[part], path = found
                notes.append(f"{part}: from {path.name} (not rerun)")
    write_summary(res, notes, b.out_dir, progress)
    return res
