"""Evidence for the thesis reproduction, turned into result files: why heel-only models need a wider
margin (the envelope), finished learning-study sweeps and multi-seed runs as tables, and reproduce
runs made in parallel processes merged into one result. Run by benchmarks/thesis_envelope.py,
thesis_learning_report.py, thesis_seed_check.py and reproduce_combine.py.
"""

from __future__ import annotations

import csv
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

from jaxexo.evaluation.machine import write_result
from jaxexo.evaluation.reproduce import compact, run_names, tables
from jaxexo.physics import geometry as g
from jaxexo.summary import table


def _write(name: str, payload: dict, lines: list[str], out_dir) -> dict:
    """write_result with the paths printed, as every report here ends."""
    for p in write_result(name, payload, "\n".join(lines), out_dir):
        print(p)
    return payload


ENVELOPE_NOTE = """\
A policy that sees only the heel (y, z) cannot tell Base 1-3 apart, so the best it can do is keep the
safety distance min_dt (eq 2.35) from all three at once (same centre, as in the thesis layouts). This
script measures, on a dense grid of flat-foot positions (heel y, z; the 20 cm heel-toe segment), whether
every position that keeps min_dt from Base 1-3 (or from Base 3 alone) is also clear of the test
triangle and half-circle (thesis Table 3.1), with the exact segment-polygon clearance of
jaxexo.physics.geometry. Writes benchmarks/results/thesis-learning-envelope_<date>_<machine>.{json,md}."""


def run_envelope(out_dir) -> dict:
    """ENVELOPE_NOTE's measurement on a 1 mm grid, written as thesis-learning-envelope_<date>_<machine>.*"""
    center, foot = 0.45, 0.20
    kinds = ("base1", "base2", "base3", "triangle", "half_circle")
    obs = {k: g.Obstacle.named(k, center_y=center) for k in kinds}
    ys = np.linspace(center - 0.45, center + 0.20, 651)  # 1 mm steps
    zs = np.linspace(0.0, 0.40, 401)  # 1 mm steps
    y, z = np.meshgrid(ys, zs)
    heel = np.stack([y.ravel(), z.ravel()], -1)
    clear = {
        k: g.foot_clearance(np, heel, foot, o.outline_array(len(o.unit_vertices)))
        for k, o in obs.items()
    }
    rows = []
    for margin in (0.03, 0.06):
        for basis in (("base3",), ("base1", "base2", "base3")):
            safe = np.all([clear[k] >= margin for k in basis], axis=0)
            for test in ("triangle", "half_circle"):
                bad = safe & g.foot_collides(np, clear[test])
                rows.append(
                    {
                        "min_dt_m": margin,
                        "kept_from": "+".join(basis),
                        "test_obstacle": test,
                        "safe_positions": int(safe.sum()),
                        "safe_but_colliding": int(bad.sum()),
                        "min_clearance_m": float(clear[test][safe].min()),
                    }
                )
    keys = ("kept_from", "test_obstacle", "safe_positions", "safe_but_colliding")
    lines = [
        "# Thesis learning study: envelope",
        "",
        ENVELOPE_NOTE,
        "",
        f"Grid: heel y {ys[0]:.2f}-{ys[-1]:.2f} m x z 0-0.40 m, 1 mm steps ({heel.shape[0]} positions); "
        "command: `python benchmarks/thesis_envelope.py`.",
        "",
        *table(
            "min_dt cm|kept from|test obstacle|positions kept|of which collide with the test obstacle|"
            "min clearance to it cm".split("|"),
            [
                (
                    f"{100 * r['min_dt_m']:.0f}",
                    *(r[k] for k in keys),
                    f"{100 * r['min_clearance_m']:.2f}",
                )
                for r in rows
            ],
            "rllrrr",
        ),
    ]
    lines += [
        "",
        "With 6 cm from each of Base 1-3 every kept position is at least 1.1 cm clear of the half-circle "
        "and 6 cm of the triangle; with jaxexo's default 3 cm, thousands of kept positions touch the half-circle, "
        "so a policy that is merely safe for the training obstacles can hit it.",
    ]
    return _write("thesis-learning-envelope", {"rows": rows}, lines, out_dir)


COLS = (
    "success",
    "accuracy",
    "held_out_success",
    "train_success",
    "eval_return",
    "episodes",
    "updates",
    "wall_s",
)
PCT = {"success", "accuracy", "held_out_success", "train_success"}


def _fmt(col: str, v: str) -> str:
    if v in ("", "nan"):
        return "-"
    x = float(v)
    return (
        f"{100 * x:.1f}"
        if col in PCT
        else (f"{x:.0f}" if col in ("episodes", "updates") else f"{x:.2f}")
    )


def learning_report(study: str, sweep_file: str, sweep_dir: str, out_dir, note: str = "") -> dict:
    """A finished ``jaxexo sweep`` of configs/sweeps/thesis_*.toml as thesis-learning-<study>_<date>_<machine>.*:
    every agent's row and the mean over seeds per configuration."""
    sweep = json.loads((Path(sweep_dir) / "sweep.json").read_text())
    axes = list(sweep.get("sweep", {}).get("grid", {}))
    rows = list(csv.DictReader(open(Path(sweep_dir) / "results.csv")))
    head = [*axes, "seed", "strict success %", "accuracy % (eq 3.1)", "held-out success %"]
    head += ["train success % (last 10 %)", "greedy return", "episodes", "updates", "wall s"]
    align = "l" * (len(axes) + 1) + "r" * len(COLS)
    lines = [
        f"# Thesis learning study: {study}",
        "",
        note,
        "",
        f"Command: `jaxexo sweep {sweep_file} --out DIR` (then `python benchmarks/thesis_learning_report.py "
        f"{study} {sweep_file} DIR`). Scores: greedy rollouts on 1000 test layouts (the five thesis obstacles "
        "x three pivot conditions; triangle and half-circle never trained on). Wall s: the compiled group "
        "the agent ran in, all its agents together, on this machine (busy, shared by other jobs).",
        "",
        "## Per configuration (mean over seeds)",
        "",
    ]
    groups = defaultdict(list)
    for r in rows:
        groups[tuple(r[a] for a in axes)].append(r)
    means = {
        key: [
            str(sum(float(r[c]) for r in rs) / len(rs))
            if all(r[c] not in ("", "nan") for r in rs)
            else "nan"
            for c in COLS
        ]
        for key, rs in groups.items()
    }
    per_config = [
        (*key, len(groups[key]), *(_fmt(c, m) for c, m in zip(COLS, ms)))
        for key, ms in means.items()
    ]
    lines += table([*axes, "seeds", *head[len(axes) + 1 :]], per_config, align)
    lines += ["", "## Every agent", ""]
    lines += table(
        head,
        [(*(r[a] for a in axes), r["seed"], *(_fmt(c, r[c]) for c in COLS)) for r in rows],
        align,
    )
    payload = {
        "study": study,
        "sweep_file": sweep_file,
        "axes": axes,
        "note": note,
        "rows": [{k: r[k] for k in (*axes, "seed", *COLS)} for r in rows],
    }
    return _write(f"thesis-learning-{study}", payload, lines, out_dir)


def seed_check(note: str, runs: list[str], out_dir) -> dict:
    """Run directories given as MODEL=RUN_DIR:SEED, their eval.json figures one row each, written as
    thesis-seeds_<date>_<machine>.*"""
    lines = [
        "# Thesis learns configs over seeds (jaxexo train, the reproduce driver)",
        "",
        note,
        "",
        "Command per row: `jaxexo train jaxexo/config/thesis/<config>.toml --out DIR --seed S` (seed 0: the "
        "run of `jaxexo reproduce --variant both`). Scores: the run's eval.json, greedy JAX rollouts of the "
        "exported (best validated) policy on the 1000 test layouts (five thesis obstacles x three pivot "
        "conditions), raw moves, no smoothing.",
        "",
    ]
    rows, cells = [], []
    for spec in runs:
        model, rest = spec.split("=", 1)
        run, seed = rest.rsplit(":", 1)
        ev = json.loads((Path(run) / "eval.json").read_text())
        row = {
            "config": model,
            "seed": int(seed),
            "success": ev["success_raw"],
            "accuracy": ev["accuracy"],
            "reached_goal": ev["reached_goal"],
            "held_out_success": ev["held_out"]["success_raw"],
            "selected_chunk": ev.get("selected_chunk"),
            "train_seconds": ev["train_seconds"],
        }
        rows.append(row)
        pct = (
            f"{100 * row[k]:.1f}"
            for k in ("success", "accuracy", "reached_goal", "held_out_success")
        )
        cells.append((model, seed, *pct, row["selected_chunk"], f"{row['train_seconds']:.1f}"))
    head = "config|seed|strict success %|accuracy % (eq 3.1)|reached goal %|held-out success %"
    lines += table(head.split("|") + ["selected chunk", "train s"], cells)
    return _write("thesis-seeds", {"note": note, "rows": rows}, lines, out_dir)


# The figures the reproduce result keeps (it stays under 100 KB).
KEEP = (
    "n",
    "accuracy",
    "success",
    "reached_goal",
    "time_ms_mean",
    "knee_swing_mean_deg",
    "hip_swing_mean_deg",
)


def _slim(r: dict) -> dict:
    out = {k: r[k] for k in KEEP if k in r}
    for group in ("by_kind", "by_pivot"):
        if group in r:
            out[group] = {x: {k: v[k] for k in KEEP if k in v} for x, v in r[group].items()}
    for k in ("batch_1000_ms", "device"):
        if r.get(k) is not None:
            out[k] = r[k]
    return out


def _run_result(name: str, dirs: list[Path]) -> dict | None:
    """A run's figures: its runs/<name>/reproduce_entry.json in the first folder that has one, else its
    entry in the first reproduce.json that has it."""
    for d in dirs:
        e = d / "runs" / name / "reproduce_entry.json"
        if e.exists():
            return json.loads(e.read_text())["result"]
    for d in dirs:
        j = d / "reproduce.json"
        if j.exists() and name in (data := json.loads(j.read_text())):
            return data[name]
    return None


def combine_reproduce(dirs, out_dir="benchmarks/results") -> dict:
    """The runs of several ``jaxexo reproduce --out DIR`` folders as one reproduce_<date>_<machine>.*,
    slimmed to the tabulated figures; the tables are also written to /tmp/repro/reproduce.md (that
    folder must exist)."""
    dirs = [Path(p) for p in dirs]
    results = {}
    for name in run_names(("a", "b", "c", "1", "2", "3", "final"), "both"):
        r = _run_result(name, dirs)
        if r is not None:
            results[name] = r
    for r in results.values():
        for gen in ("rl", "rl_eps", "cfftg"):
            if gen in r:
                r[gen] = compact(r[gen])
    print("have", list(results))
    md = tables(results)
    Path("/tmp/repro/reproduce.md").write_text(md)
    small = {
        n: {k: (_slim(v) if k in ("rl", "rl_eps", "cfftg") else v) for k, v in r.items()}
        for n, r in results.items()
    }
    payload = json.loads(json.dumps(small))
    for p in write_result("reproduce", payload, md, out_dir):
        print(p, p.stat().st_size)
    return payload
