"""Landing benchmark: where the RL swing ends and what a complete swing costs beside CFFTG's, on the
safety sets. Run by benchmarks/bench_landing.py; method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import time

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.evaluation.machine import write_result
from jaxexo.inference import TrajectoryGenerator, time_swings
from jaxexo.physics.scenarios import batch_options
from jaxexo.summary import Summary, table
from jaxexo.swing.trajectory import assemble

from benchlib.scenes import safety_sets


def approach(heel: np.ndarray, drop: float = 0.02) -> float:
    """Forward heel travel (m) while the heel comes down its last ``drop`` m to where it ends."""
    z_end = heel[-1, 1]
    above = np.flatnonzero(heel[:, 1] > z_end + drop)
    start = above[-1] if above.size else 0
    return float(heel[-1, 0] - heel[start, 0])


def with_touch_down(batch, gen, points: int = 6) -> list:
    """The swings with a vertical touch-down appended where they end above the floor (what
    jaxexo.course did to RL swings before the generator landed them), checked again."""
    out = []
    for t in batch:
        path = t.heel
        if t.ok and path[-1, 1] > 0.0:
            drop = np.column_stack(
                [np.full(points, path[-1, 0]), np.linspace(path[-1, 1], 0.0, points + 1)[1:]]
            )
            path = np.concatenate([path, drop])
        out.append(
            assemble(
                t.method,
                gen.sp,
                [t.scene],
                [t.raw],
                path[None],
                [t.smoothing],
                duration=float(t.time[-1]),
                deviation=[t.checks.deviation],
            )[0]
        )
    return out


def run_set(gens, scenes, config) -> dict:
    kw = batch_options(scenes)
    obs = [s.obstacle for s in scenes]
    out, dur = {}, {}
    for name, gen in gens.items():
        t0 = time.perf_counter()
        batch = (
            gen.generate_batch(obs, fallback=None, **kw)
            if name == "rl"
            else gen.generate_batch(obs, **kw)
        )
        gen_s = time.perf_counter() - t0
        timed = time_swings(batch, config)
        d = np.array([t.duration for t in timed])
        end_z = batch.heel[:, -1, 1]
        end, span = Summary.of(end_z), Summary.of(d)
        dur[name] = d
        touch = added = None
        if name == "rl" and (batch.heel[:, -1, 1] > 0.0).any():
            td = np.array([t.duration for t in time_swings(with_touch_down(batch, gen), config)])
            up = batch.ok & (batch.heel[:, -1, 1] > 0.0)
            touch = Summary.of(td).median
            added = Summary.of(td[up] - d[up]).median
        out[name] = {
            "n": len(batch),
            "safe": float(batch.ok.mean()),
            "reached_goal": float(batch.reached_goal.mean()),
            "end_above_2mm": float(np.mean(end_z > 0.002)),
            "end_z_mm_max": 1000 * end.max,
            "end_z_mm_median": 1000 * end.median,
            "lift_cm_median": 100 * Summary.of(batch.heel[..., 1].max(axis=1)).median,
            "duration_s_median": span.median,
            "duration_s_p95": span.p95,
            "duration_touch_down_s_median": touch,
            "touch_down_added_s_median": added,
            "approach_mm_median": 1000 * Summary.of([approach(h) for h in batch.heel]).median,
            "retried": float(np.mean([bool(n) for n in batch.notes])),
            "raw_polyline": float(np.mean(np.isnan(batch.smoothing))),
            "generate_s": gen_s,
            "ok_mask": batch.ok,
            # per scene, for comparing two runs swing by swing
            "per_scene": {
                "duration_s": d.tolist(),
                "end_z_m": end_z.tolist(),
                "ok": batch.ok.tolist(),
            },
        }
    both = out["rl"]["ok_mask"] & out["cfftg"]["ok_mask"]
    out["rl_over_cfftg_duration_median"] = (
        Summary.of(dur["rl"][both] / dur["cfftg"][both]).median if both.any() else None
    )
    out["both_safe"] = int(both.sum())
    for name in gens:
        del out[name]["ok_mask"]
    return out


HEADER = (
    *("set", "method", "safe", "goal", "ends > 2 mm up", "end heel z max / median (mm)"),
    *("lift median (cm)", "duration median / p95 (s)", "with touch-down (s): median, added"),
    *("approach (mm)", "retried / raw polyline", "RL/CFFTG duration median"),
)


def _cells(r: dict, g: str) -> tuple[str, ...]:
    """Generator ``g``'s row on a set (``r``: the set's figures) after the set and method."""
    x, rl = r[g], g == "rl"
    touch = x["duration_touch_down_s_median"]
    return (
        *(f"{100 * x[k]:.1f} %" for k in ("safe", "reached_goal", "end_above_2mm")),
        f"{x['end_z_mm_max']:.1f} / {x['end_z_mm_median']:.1f}",
        f"{x['lift_cm_median']:.2f}",
        f"{x['duration_s_median']:.3f} / {x['duration_s_p95']:.3f}",
        "-" if touch is None else f"{touch:.3f}, +{x['touch_down_added_s_median']:.3f}",
        f"{x['approach_mm_median']:.1f}",
        f"{100 * x['retried']:.1f} / {100 * x['raw_polyline']:.1f} %" if rl else "-",
        f"{r['rl_over_cfftg_duration_median']:.3f} (n = {r['both_safe']})" if rl else "",
    )


def markdown(res: dict) -> str:
    lines = [
        f"# Landing: RL alone (fallback=None) beside CFFTG ({res['tag'] or 'current'})",
        "",
        f"Policy {res['policy']}; {res['n']} scenes per set. {res['note']}".rstrip(),
        "",
    ]
    rows = [(name, g, *_cells(r, g)) for name, r in res["sets"].items() for g in ("rl", "cfftg")]
    lines += table(HEADER, rows, "l" * 12)
    return "\n".join(lines)


def run_landing_benchmark(policy, out_dir, n: int = 300, tag: str = "", note: str = "") -> dict:
    """Both generators on the three sets, printed and written as landing[_tag]_<date>_<machine>.*;
    ``note``: a line for the report (where the policy came from)."""
    rl = TrajectoryGenerator.load(policy)
    config = rl.config
    gens = {"rl": rl, "cfftg": CFFTG(config)}
    res = {"policy": policy, "n": n, "tag": tag, "note": note, "sets": {}}
    for name, scenes in safety_sets(config, n).items():
        res["sets"][name] = run_set(gens, scenes, config)
        print(name, res["sets"][name], flush=True)
    md = markdown(res)
    write_result("landing" + (f"_{tag}" if tag else ""), res, md, out_dir)
    print(md)
    return res
