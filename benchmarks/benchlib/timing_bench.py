"""Device-timing benchmark: RL and CFFTG swings on the same scenes timed for the [device] limits and
sampled at a control rate. Writes timing_<date>_<machine>.{json,md}; method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from jaxexo.physics.scenarios import batch_options, shape_scenarios
from jaxexo.summary import Summary, table

# benchmarks/bench_timing.py's options (benchlib.runner.run_script).
OPTIONS = (
    ("--n", "n", "thesis-obstacle scenes"),
    ("--unseen", "n_unseen", "unseen-shape scenes"),
    ("--rate", "rate", "control rate, Hz"),
)


def _figures(trajs, timed, rate: float) -> dict:
    from jaxexo.swing.timing import uniform_peaks

    d = np.degrees
    dur = np.array([t.duration for t in timed])
    swing = Summary.of(dur)
    vmax = np.array(timed[0].limits.velocity)
    amax = np.array(timed[0].limits.acceleration)
    fd_v = np.array([np.abs(np.diff(t.joint_angles, axis=0) * rate).max(axis=0) for t in timed])
    fd_a = np.array(
        [np.abs(np.diff(t.joint_angles, n=2, axis=0) * rate**2).max(axis=0) for t in timed]
    )
    end_v = np.array([np.abs(np.diff(t.joint_angles, axis=0)[[0, -1]] * rate).max() for t in timed])
    uni = [uniform_peaks(t) for t in trajs]
    return {
        "n": len(timed),
        "path_ok": float(np.mean([t.ok for t in trajs])),
        "timed_ok": float(np.mean([t.ok for t in timed])),
        "swing_s_mean": swing.mean,
        "swing_s_median": swing.median,
        "swing_s_p95": swing.p95,
        "swing_s_max": swing.max,
        "within_limits": float(np.mean([t.within_limits for t in timed])),
        "fd_within_limits": float(
            np.mean(np.all(fd_v <= vmax, axis=1) & np.all(fd_a <= amax, axis=1))
        ),
        "fd_peak_vel_ratio_max": float((fd_v / vmax).max()),
        "fd_peak_acc_ratio_max": float((fd_a / amax).max()),
        "peak_hip_vel_deg_s_mean": float(d(np.maximum(fd_v[:, 0], fd_v[:, 2]).mean())),
        "peak_knee_vel_deg_s_mean": float(d(np.maximum(fd_v[:, 1], fd_v[:, 3]).mean())),
        "end_step_vel_deg_s_max": float(d(end_v.max())),
        "slowdown_mean": float(np.mean([t.slowdown for t in timed])),
        "uniform_peak_vel_deg_s_median": float(d(Summary.of([u[0].max() for u in uni]).median)),
        "uniform_peak_acc_deg_s2_median": float(d(Summary.of([u[1].max() for u in uni]).median)),
    }, dur


HEADER = (
    *("set", "generator", "n", "path ok %", "timed ok %", "swing s mean", "median", "p95", "max"),
    *("within limits % (FD)", "peak hip deg/s", "peak knee deg/s", "end step deg/s max"),
    *("timing ms/swing", "uniform 1 s: peak deg/s / deg/s² (median)"),
)


def _cells(f: dict) -> tuple[str, ...]:
    """One generator's row of the main table after the set and generator."""
    return (
        str(f["n"]),
        *(f"{100 * f[k]:.1f}" for k in ("path_ok", "timed_ok")),
        *(f"{f['swing_s_' + k]:.3f}" for k in ("mean", "median", "p95", "max")),
        f"{100 * f['fd_within_limits']:.1f}",
        *(f"{f[k]:.0f}" for k in ("peak_hip_vel_deg_s_mean", "peak_knee_vel_deg_s_mean")),
        f"{f['end_step_vel_deg_s_max']:.2f}",
        f"{f['timing_ms_per_swing']:.1f}",
        f"{f['uniform_peak_vel_deg_s_median']:.0f} / {f['uniform_peak_acc_deg_s2_median']:.0f}",
    )


def _ratio_cells(c: dict) -> tuple[str, ...]:
    return (
        f"{100 * c['rl_not_longer_fraction']:.1f}",
        f"{c['duration_ratio_mean']:.3f}",
        f"{c['duration_ratio_median']:.3f}",
    )


def run_timing_benchmark(
    policy: str | Path, out_dir: str | Path, n: int = 1000, n_unseen: int = 300, rate: float = 100.0
) -> dict:
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.compare import make_scenarios
    from jaxexo.evaluation.machine import write_result
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.swing.timing import DeviceLimits, time_swings

    rl = TrajectoryGenerator.load(policy)
    gens = {"rl": rl, "cfftg": CFFTG(rl.config)}
    sets = {"thesis": make_scenarios(rl.config, "test", n), "unseen": shape_scenarios(n_unseen)}
    lim = DeviceLimits.from_config(rl.config)
    payload = {"policy": str(policy), "rate_hz": rate, "limits": lim.to_dict(), "sets": {}}
    lines = [
        "# Device-ready swings: RL vs CFFTG, same scenes, same device limits",
        "",
        f"Policy `{policy}`; every swing timed by jaxexo.swing.timing (TOPP on the joint path, "
        f"rest-to-rest) and sampled at {rate:g} Hz. Limits (hip, knee): "
        f"{np.degrees(lim.velocity[0]):.0f}, {np.degrees(lim.velocity[1]):.0f} deg/s; "
        f"{np.degrees(lim.acceleration[0]):.0f}, {np.degrees(lim.acceleration[1]):.0f} deg/s². "
        "Peaks and limit checks are finite differences of the exported joint angles at the control rate.",
        "",
    ]
    rows = []
    for set_name, sc in sets.items():
        res, durs = {}, {}
        for name, g in gens.items():
            batch = g.generate_batch([s.obstacle for s in sc], **batch_options(sc))
            trajs = list(batch)
            t0 = time.perf_counter()
            timed = time_swings(trajs, g.config, rate=rate)
            ms = (time.perf_counter() - t0) * 1e3 / len(trajs)
            fig, durs[name] = _figures(trajs, timed, rate)
            fig["timing_ms_per_swing"] = ms
            kinds = np.array([s.kind for s in sc])
            fig["by_kind_swing_s_mean"] = {
                k: float(durs[name][kinds == k].mean()) for k in dict.fromkeys(kinds)
            }
            res[name] = fig
            rows.append((set_name, name, *_cells(fig)))
        ratio = Summary.of(durs["rl"] / durs["cfftg"])
        res["rl_vs_cfftg"] = {
            "rl_not_longer_fraction": float(np.mean(durs["rl"] <= durs["cfftg"] + 1e-9)),
            "duration_ratio_mean": ratio.mean,
            "duration_ratio_median": ratio.median,
        }
        payload["sets"][set_name] = res
    sets = payload["sets"]
    lines += [*table(HEADER, rows, "ll" + "r" * 12 + "l"), ""]
    lines += table(
        ("set", "RL swing ≤ CFFTG swing (% of scenes)", "RL / CFFTG duration, mean", "median"),
        [(s, *_ratio_cells(res["rl_vs_cfftg"])) for s, res in sets.items()],
    )
    lines += ["", "Swing mean by obstacle kind (s):", ""]
    lines += table(
        ("set", "kind", "RL", "CFFTG"),
        [
            (s, k, f"{v:.3f}", f"{res['cfftg']['by_kind_swing_s_mean'][k]:.3f}")
            for s, res in sets.items()
            for k, v in res["rl"]["by_kind_swing_s_mean"].items()
        ],
        "llrr",
    )
    md = "\n".join(lines)
    jpath, mpath = write_result("timing", payload, md, out_dir)
    print(md)
    print(f"wrote {jpath}, {mpath}")
    return payload
