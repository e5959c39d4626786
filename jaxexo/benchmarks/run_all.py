"""``jaxexo bench``: every benchmark in one run, each writing its own result files, then a summary.

Parts (``skip`` any of them): ``env`` (jaxexo.benchmarks.env_bench), ``train`` (train_bench: trainer
throughput and the default and thesis configs' training runs), ``generate`` (generate_bench: the
NumPy generator), ``compare`` (jaxexo.evaluation.compare: RL generator against CFFTG on the same 1000 test
scenarios, timed in one process), ``baseline`` (baseline_bench: jaxexo's trainer against the
thesis-style PyTorch trainer; skipped with a note when torch is not installed), ``course``
(course_bench: walks over drawn courses, RL alone against CFFTG on the same footholds). The summary table
(summary_<date>_<machine>.md, shown in the README) is built from the figures the parts return.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

PARTS = ("env", "train", "generate", "compare", "baseline", "course")
ROOT = Path(__file__).resolve().parent.parent.parent


def summary_rows(res: dict) -> list[tuple[str, str, str]]:
    """(figure, measured, target or thesis) rows from the parts' results."""
    rows = []
    if "env" in res:
        for layout, results in res["env"].items():
            for r in results:
                if r["num_envs"] == 4096:
                    rows.append(
                        (
                            f"environment ({layout}), 4096 envs, env-steps/s",
                            f"{r['env_steps_per_s'] / 1e6:.2f} M",
                            ">= 5 M" if layout == "default" else "",
                        )
                    )
    if "train" in res:
        for r in res["train"]["throughput"]:
            if r["trace"] == "forward" and r.get("num_minibatches") == 4:
                rows.append(
                    (
                        "trainer, thesis network, 4096 envs, env-steps/s",
                        f"{r['env_steps_per_s'] / 1e6:.2f} M",
                        ">= 1 M",
                    )
                )
        for name, r in res["train"]["runs"].items():
            rows.append(
                (
                    f"`jaxexo train {Path(name).name}`: wall s, strict success (raw moves)",
                    f"{r['train_seconds']:.1f} s, {r.get('success_raw', r.get('success')):.3f}",
                    "<= 60 s, >= 0.99" if name.endswith("default.toml") else "< 30 s",
                )
            )
    if "generate" in res:
        g = res["generate"]
        rows.append(
            (
                "RL generator (shielded), one swing, median (CFFTG side by side), held-out scenes",
                f"{g['single_ms']['rl']['median']:.3f} ms (CFFTG {g['single_ms']['cfftg']['median']:.3f} ms)",
                "<= 1.0 ms and <= 1.5x CFFTG (thesis ~3 ms)",
            )
        )
        bt = g["batch_ms"]
        rows.append(
            (
                "RL generator, batch of 1000 (default / single-threaded BLAS)",
                f"{bt['default_threads']['rl'] * 1000 / g['n']:.1f} / {bt['single_thread_blas']['rl'] * 1000 / g['n']:.1f} ms",
                "<= CFFTG's and <= 150 ms (thesis 1764 ms)",
            )
        )
        rows.append(
            ("`import jaxexo.inference`, cold", f"{g['import_s']['median']:.3f} s", "<= 0.3 s")
        )
    if "compare" in res:
        for name, r in res["compare"].items():
            rows.append(
                (
                    f"{name} on {r['n']} test scenarios: success / accuracy / median ms / batch 1000 ms",
                    f"{r['success']:.3f} / {r['accuracy']:.3f} / {r['time_ms_median']:.3f} / {r['batch_1000_ms']:.1f}",
                    "RL success >= CFFTG's, median <= CFFTG's"
                    if name == "rl"
                    else "thesis CFFTG ~2 ms",
                )
            )
    if "baseline" in res:
        t = res["baseline"]["throughput"]
        rows.append(
            (
                "trainer vs thesis-style PyTorch trainer, env-steps/s",
                f"{t['jaxexo']['env_steps_per_s']:,.0f} vs {t['baseline']['env_steps_per_s']:,.0f} "
                f"= {t['ratio']:,.0f}x",
                ">= 1000x",
            )
        )
        for e in res["baseline"]["time_to_success"]["reach"].values():
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
    if "course" in res:
        c = res["course"]
        rows.append(
            (
                f"walks over {c['planned']} courses ({c['courses_drawn']} drawn, {c['refused']} refused): every "
                "swing safe, RL alone / CFFTG",
                f"{100 * c['rl_alone_success']:.1f} % / {100 * c['cfftg_success']:.1f} %",
                "RL >= 99 %",
            )
        )
        r = c["duration_ratio_rl_over_cfftg"]["median"]
        rows.append(
            (
                "walk duration at the device limits, RL / CFFTG, median over courses",
                "-" if r is None else f"{r:.3f}",
                "<= 1",
            )
        )
        x = c["per_step_over_one_swing_median"]
        rows.append(
            (
                "walk planning time per step / one swing's (CPU time)",
                "-" if x is None else f"{x:.2f}x",
                "<= 1.5x",
            )
        )
    return rows


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
    import json

    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result

    out_dir = Path(out_dir or ROOT / "benchmarks" / "results")
    skipped = {s.strip() for s in skip.split(",") if s.strip()}
    unknown = skipped - set(PARTS)
    if unknown:
        raise ValueError(f"--skip: unknown part {sorted(unknown)[0]!r} (parts: {', '.join(PARTS)})")
    default = ROOT / "configs" / "default.toml"
    res: dict = {}
    notes: list[str] = []
    if "env" not in skipped:
        from jaxexo.benchmarks.env_bench import run_env_benchmark

        res["env"] = run_env_benchmark(
            load_config(default), "default", [1, 256, 4096, 16384], out_dir
        )
    if "train" not in skipped:
        from jaxexo.benchmarks.train_bench import run_train_benchmark

        thesis = [
            str(ROOT / "configs" / "thesis" / f"{n}.toml")
            for n in ("a", "b", "c", "1", "2", "3", "final")
        ]
        res["train"] = run_train_benchmark(out_dir, str(default), thesis, progress)
    with tempfile.TemporaryDirectory() as tmp:
        if policy is None and ({"generate", "compare", "course"} - skipped):
            from jaxexo.train.driver import run_training

            progress("training configs/default.toml for the generator benchmarks")
            run_training(load_config(default), Path(tmp) / "run", progress=False)
            policy = Path(tmp) / "run" / "policy.npz"
        if "generate" not in skipped:
            from jaxexo.benchmarks.generate_bench import run_generate_benchmark

            res["generate"] = run_generate_benchmark(policy, out_dir, n, progress)
        if "compare" not in skipped:
            from jaxexo.evaluation.compare import run_eval
            from jaxexo.evaluation.report import markdown

            report = run_eval(
                policy, Path(tmp) / "eval", "cfftg", "test", n, figures=False, batch_size=batch_size
            )
            res["compare"] = report
            write_result(
                "compare",
                json.loads(json.dumps(report)),
                markdown(report, f"RL generator vs CFFTG, {n} test scenarios", []),
                out_dir,
            )
    if "course" not in skipped:
        from jaxexo.benchmarks.course_bench import run_course_benchmark

        res["course"] = run_course_benchmark(policy, out_dir, courses, progress=progress)
    if "baseline" not in skipped:
        try:
            import torch  # noqa: F401
        except ImportError:
            notes.append(
                'baseline skipped: PyTorch is not installed (pip install -e ".[train,bench]")'
            )
        else:
            from jaxexo.benchmarks.baseline_bench import run_baseline_benchmark

            res["baseline"] = run_baseline_benchmark(
                out_dir, str(default), baseline_seconds=baseline_seconds, progress=progress
            )
    # Parts skipped this time: their latest results in out_dir, if any, so the summary stays whole.
    for part in PARTS:
        if part not in res:
            found = latest_result(out_dir, part)
            if found is not None:
                res[part], path = found
                notes.append(f"{part}: from {path.name} (not rerun)")
    lines = [
        "# jaxexo benchmark summary",
        "",
        "| figure | measured | target / thesis |",
        "|---|---|---|",
    ]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in summary_rows(res)]
    lines += [""] + [f"- {n}" for n in notes]
    md = "\n".join(lines)
    write_result("summary", {"rows": summary_rows(res), "notes": notes}, md, out_dir)
    progress(md)
    return res
