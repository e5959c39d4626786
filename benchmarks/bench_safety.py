"""Safe-swing benchmark: how often each generator returns a safe swing (exact clearance of
the moving foot >= env.min_clearance, goal, no backward heel, joint limits, leg length), and the
number of swings flagged safe that a 10x denser look at the same curve contradicts (must be 0).

Scenes: the thesis's five obstacles with shifted layouts (start 0-10 cm, obstacle anywhere in the gap)
and shapes never trained on (random rectangles, wedges, thin poles, profiles with several bumps), every
pivot condition (jaxexo.inference.scenarios.safety_scenarios). Generators: the RL swing alone
(fallback none), the default combination (CFFTG when the RL swing is not safe), CFFTG alone.
Writes benchmarks/results/safety_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_safety.py RUN_DIR/policy.npz [--n 2000]
(train one first: jaxexo train --out RUN_DIR)"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.inference.cfftg import plan_basis
from jaxexo.evaluation.machine import machine_info, write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference import smoothing as sm
from jaxexo.inference.clearing import clear_smooth
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import geometry, swept

FACTOR = 10


def dense_curve(t, cfftg: CFFTG, factor: int = FACTOR) -> np.ndarray:
    """The trajectory's own curve at factor x its sampling (every original sample included)."""
    dense_n = factor * (len(t.heel) - 1) + 1
    if t.method.startswith("cfftg"):
        # The same polynomial, sampled densely: apex fraction and height from its via points, the
        # height shape phi_k the one that reproduces its N samples.
        sc = t.scene
        frac = (t.raw[1, 0] - sc.start_y) / (sc.goal_y - sc.start_y)
        h = t.raw[1, 1]
        phi_n = plan_basis(len(t.heel))[3]
        k = int(np.argmin(np.abs(h * phi_n - t.heel[None, :, 1]).max(axis=1)))
        s, mj, g, phi = plan_basis(dense_n)
        y = sc.start_y + (sc.goal_y - sc.start_y) * (mj + 64.0 * (frac - 0.5) * g)
        return np.column_stack([y, h * phi[k]])
    if any("jaxexo.inference.clearing" in note for note in t.notes):
        # the corrected spline, evaluated from the same coefficients at the dense parameters
        return clear_smooth(t.raw, t.scene.outline, cfftg.sp.foot_length, cfftg.sp.min_clearance, len(t.heel),
                            t.smoothing, dense_points=dense_n)[3]
    if np.isnan(t.smoothing) or t.smoothing == 0:
        return np.concatenate([sm.linear_resample(t.raw, dense_n), sm.distinct(t.raw)])
    return sm.smooth_paths([t.raw], dense_n, t.smoothing)[0]


def recheck(batch, cfftg: CFFTG, margin: float, tol: float) -> dict:
    false_safe, dense_min = 0, []
    for i in np.flatnonzero(batch.ok):
        t = batch[i]
        d = dense_curve(t, cfftg)
        c = geometry.foot_clearance(np, d, cfftg.sp.foot_length, t.scene.outline).min()
        y = d[: FACTOR * (len(t.heel) - 1) + 1, 0]
        back = float(np.max(np.maximum.accumulate(y) - y))
        dense_min.append(c - t.checks.min_clearance)
        false_safe += int(c < margin or back > tol)
    return {"false_safe": false_safe, "rechecked": int(batch.ok.sum()),
            "dense_minus_guaranteed_m_min": float(min(dense_min)) if dense_min else None}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("policy", help="policy.npz")
    p.add_argument("--n", type=int, default=2000, help="scenes per set (thesis five; unseen shapes)")
    a = p.parse_args()
    rl = TrajectoryGenerator.load(a.policy)
    cfftg = CFFTG(rl.config)
    margin, tol = rl.config.env.min_clearance, rl.config.env.backward_tolerance
    rows, payload = [], {"policy": str(a.policy), "margin_m": margin, "backward_tolerance_m": tol,
                         "dense_factor": FACTOR, "sets": {}}
    for name, unseen in (("thesis five, shifted", False), ("unseen shapes", True)):
        sc = safety_scenarios(rl.config, a.n, unseen=unseen)
        kw = dict(pivot=[s["pivot"] for s in sc], start_y=[s["start_y"] for s in sc],
                  step_length=[s["step_length"] for s in sc])
        obs = [s["obstacle"] for s in sc]
        out = {}
        for gname, make in (("rl", lambda: rl.generate_batch(obs, fallback=None, **kw)),
                            ("rl+cfftg", lambda: rl.generate_batch(obs, fallback="cfftg", **kw)),
                            ("cfftg", lambda: cfftg.generate_batch(obs, **kw))):
            t0 = time.perf_counter()
            b = make()
            secs = time.perf_counter() - t0
            rc = recheck(b, cfftg, margin, tol)
            close = np.array([b[i].checks.min_clearance for i in range(len(b))])
            back = np.array([float(swept.backward_motion(np, b.heel[i, :, 0])) for i in range(len(b))])
            out[gname] = {"n": len(b), "safe_rate": float(b.ok.mean()), "seconds": secs,
                          "within_1cm_rate": float((close < 0.01).mean()),
                          "median_guaranteed_clearance_m": float(np.median(close)),
                          "backward_over_5mm_rate": float((back > 0.005).mean()),
                          "fallback_rate": float(np.mean([b[i].method == "cfftg-fallback" for i in range(len(b))])),
                          **rc}
            r = out[gname]
            rows.append(f"| {name} | {gname} | {r['n']} | {100 * r['safe_rate']:.1f} | "
                        f"{100 * r['within_1cm_rate']:.1f} | {100 * r['median_guaranteed_clearance_m']:.2f} | "
                        f"{100 * r['backward_over_5mm_rate']:.1f} | {100 * r['fallback_rate']:.1f} | "
                        f"{r['rechecked']} | {r['false_safe']} | {r['seconds']:.1f} |")
        payload["sets"][name] = out
    info = machine_info()
    payload["machine"] = info
    md = "\n".join([
        "# Safe-swing benchmark", "",
        f"Policy `{a.policy}`; margin env.min_clearance = {100 * margin:.1f} cm, backward tolerance "
        f"{1000 * tol:.1f} mm; {info['cpu']}, {info['cores']} cores. A swing is safe when the exact clearance "
        "of the moving foot (between samples, less the curve's deviation bound) keeps the margin, the goal is "
        "reached, the heel never moves backward by more than the tolerance, and joint limits and leg length "
        f"hold. False safe: swings flagged safe whose curve, sampled {FACTOR}x more densely (exact per-sample "
        "foot distance), comes within the margin or moves the heel back more than the tolerance.", "",
        "| scenes | generator | n | safe % | guaranteed clearance < 1 cm % | median guaranteed clearance cm | "
        "heel backward > 5 mm % | CFFTG fallback % | rechecked at 10x | false safe | seconds |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|", *rows, ""])
    paths = write_result("safety", payload, md, Path(__file__).resolve().parent / "results")
    print(md)
    print("wrote", *paths)


if __name__ == "__main__":
    main()
