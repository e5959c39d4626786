"""Continuation paths benchmark (replanning in flight): RL swings planned over unseen shapes, the obstacle
then made 30-60 % taller than planned and the foot's state taken at 20-40 % of the swing where the
foot is still clear of the taller one; from each state the RL continuation alone
(``TrajectoryGenerator.continuation(..., fallback=None)``), CFFTG's (``CFFTG.continuation``) and the
RL one with the CFFTG fallback: how often each passes its checks on the new obstacle, how often an
independent dense clearance (the foot at 10x more points on each path's polyline) finds one called
ok within the margin, and the CPU time of one continuation (time.process_time, median and p99 over
repeated calls).

Writes benchmarks/results/continuation_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_continuation.py [--policy tests/data/reference/policy.npz] [--n 100]
"""

import argparse
import dataclasses
import os
import time
from pathlib import Path

import numpy as np

from jaxexo.baselines.cfftg import CFFTG
from jaxexo.evaluation.machine import write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import geometry
from jaxexo.physics.geometry import Obstacle
from jaxexo.swing.replan import foot_state
from jaxexo.swing.timing import time_swing

ROOT = Path(__file__).resolve().parent.parent


def taller(ob, factor):
    if ob.shape == "profile":
        return Obstacle.profile(ob.outline * [1.0, factor])
    return dataclasses.replace(ob, height=ob.height * factor)


def dense_clearance(heel, foot_length, outline, factor=10):
    s = np.linspace(0.0, len(heel) - 1, factor * (len(heel) - 1) + 1)
    dense = np.column_stack([np.interp(s, np.arange(len(heel)), heel[:, k]) for k in (0, 1)])
    return float(geometry.foot_clearance(np, dense, foot_length, outline).min())


def cases(gen, n, seed=59):
    """n (old scene, new scene, state) cases over unseen shapes (safety_scenarios, unseen)."""
    rng = np.random.default_rng(seed)
    out, tried = [], 0
    for s in safety_scenarios(gen.config, 4 * n, seed=seed, unseen=True):
        tr = gen.generate(s.obstacle, pivot=s.pivot, start_y=s.start_y, step_length=s.step_length)
        tried += 1
        if not tr.ok:
            continue
        sw = time_swing(tr, gen.config)
        old = tr.scene
        new = gen.scene(
            taller(s.obstacle, rng.uniform(1.3, 1.6)),
            pivot_y=old.pivot_y,
            start_y=old.start_y,
            step_length=old.goal_y - old.start_y,
        )
        st = foot_state(sw, rng.uniform(0.2, 0.4) * sw.duration)
        c = geometry.foot_clearance(np, st.heel[None], gen.sp.foot_length, new.outline)[0]
        if c >= gen.sp.min_clearance:
            out.append((old, new, st))
        if len(out) == n:
            break
    return out, tried


def cpu_ms(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        times.append(1e3 * (time.process_time() - t0))
    return times


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", default=str(ROOT / "tests" / "data" / "reference" / "policy.npz"))
    p.add_argument("--n", type=int, default=100)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    a = p.parse_args()
    gen = TrajectoryGenerator.load(a.policy)
    cf = CFFTG(gen.config)
    rows, tried = cases(gen, a.n)
    methods = {
        "rl": lambda o, n, s: gen.continuation(n, s, fallback=None, swing_scene=o),
        "cfftg": lambda o, n, s: cf.continuation(n, s, swing_scene=o),
        "rl+cfftg": lambda o, n, s: gen.continuation(n, s, fallback="cfftg", swing_scene=o),
    }
    policy = os.path.relpath(a.policy, ROOT)
    report = {"policy": policy, "cases": len(rows), "swings_tried": tried, "methods": {}}
    for name, fn in methods.items():
        fn(*rows[0])  # warm caches (the fallback planner's constants, the spline operators)
        ok, unsafe, times, plans_fell = 0, 0, [], 0
        for old, new, st in rows:
            traj = fn(old, new, st)
            times += cpu_ms(lambda: fn(old, new, st), a.repeats)
            dense = dense_clearance(traj.heel, gen.sp.foot_length, new.outline)
            ok += traj.ok
            unsafe += bool(traj.ok and dense < gen.sp.min_clearance)
            plans_fell += traj.method == "cfftg-fallback"
        report["methods"][name] = {
            "ok": ok,
            "ok_pct": 100.0 * ok / len(rows),
            "ok_but_dense_within_margin": unsafe,
            "cfftg_fallbacks": plans_fell,
            "cpu_ms_median": float(np.median(times)),
            "cpu_ms_p99": float(np.percentile(times, 99)),
            "calls_timed": len(times),
        }
    lines = [
        f"# Continuation paths ({len(rows)} mid-swing states, obstacle 30-60 % taller, at "
        "20-40 % of the swing)",
        "",
        "| continuation | ok | ok but dense check within margin | CPU ms median | p99 |",
        "|---|---|---|---|---|",
    ]
    for name, m in report["methods"].items():
        lines.append(
            f"| {name} | {m['ok']}/{len(rows)} ({m['ok_pct']:.1f} %) | "
            f"{m['ok_but_dense_within_margin']} | {m['cpu_ms_median']:.2f} | {m['cpu_ms_p99']:.2f} |"
        )
    report["load_average"] = os.getloadavg()
    paths = write_result("continuation", report, "\n".join(lines), a.out)
    print("\n".join(lines), *paths, sep="\n")


if __name__ == "__main__":
    main()
