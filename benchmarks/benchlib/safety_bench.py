"""Safe-swing benchmark: how often each generator returns a safe swing, and how many swings flagged safe
a 10x denser look at the same curve contradicts (must be 0). Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import time

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.baselines.cfftg import plan_basis
from jaxexo.evaluation.machine import machine_info, write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import geometry, swept
from jaxexo.physics.scenarios import batch_options
from jaxexo.summary import Summary, table
from jaxexo.swing import smoothing as sm
from jaxexo.swing.clearing import clear_smooth

from benchlib.scenes import SHAPES, THESIS_FIVE
from benchlib.swing_quality_bench import CLEARING

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
    if any(CLEARING in note for note in t.notes):
        # the corrected spline, evaluated from the same coefficients at the dense parameters
        return clear_smooth(
            t.raw,
            t.scene.outline,
            cfftg.sp.foot_length,
            cfftg.sp.min_clearance,
            len(t.heel),
            t.smoothing,
            dense_points=dense_n,
        )[3]
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
    return {
        "false_safe": false_safe,
        "rechecked": int(batch.ok.sum()),
        "dense_minus_guaranteed_m_min": float(min(dense_min)) if dense_min else None,
    }


def generator_figures(b, cfftg: CFFTG, margin: float, tol: float, seconds: float) -> dict:
    """One generator's figures on a batch of swings generated in ``seconds``."""
    rc = recheck(b, cfftg, margin, tol)
    close = np.array([b[i].checks.min_clearance for i in range(len(b))])
    back = np.array([float(swept.backward_motion(np, b.heel[i, :, 0])) for i in range(len(b))])
    return {
        "n": len(b),
        "safe_rate": float(b.ok.mean()),
        "seconds": seconds,
        "within_1cm_rate": float((close < 0.01).mean()),
        "median_guaranteed_clearance_m": Summary.of(close).median,
        "backward_over_5mm_rate": float((back > 0.005).mean()),
        "fallback_rate": float(np.mean([b[i].method == "cfftg-fallback" for i in range(len(b))])),
        **rc,
    }


HEADER = (
    *("scenes", "generator", "n", "safe %", "guaranteed clearance < 1 cm %"),
    *("median guaranteed clearance cm", "heel backward > 5 mm %", "CFFTG fallback %"),
    *("rechecked at 10x", "false safe", "seconds"),
)


def _cells(r: dict) -> tuple[str, ...]:
    """One generator's figures on a set, as the table's cells after the set and generator."""
    rates = ("safe_rate", "within_1cm_rate", "median_guaranteed_clearance_m")
    return (
        str(r["n"]),
        *(f"{100 * r[k]:.{2 if k.startswith('median') else 1}f}" for k in rates),
        *(f"{100 * r[k]:.1f}" for k in ("backward_over_5mm_rate", "fallback_rate")),
        *(str(r[k]) for k in ("rechecked", "false_safe")),
        f"{r['seconds']:.1f}",
    )


def markdown(policy, margin: float, tol: float, info: dict, rows: list[tuple]) -> str:
    return "\n".join(
        [
            "# Safe-swing benchmark",
            "",
            f"Policy `{policy}`; margin env.min_clearance = {100 * margin:.1f} cm, backward tolerance "
            f"{1000 * tol:.1f} mm; {info['cpu']}, {info['cores']} cores. A swing is safe when the exact clearance "
            "of the moving foot (between samples, less the curve's deviation bound) keeps the margin, the goal is "
            "reached, the heel never moves backward by more than the tolerance, and joint limits and leg length "
            f"hold. False safe: swings flagged safe whose curve, sampled {FACTOR}x more densely (exact per-sample "
            "foot distance), comes within the margin or moves the heel back more than the tolerance.",
            "",
            *table(HEADER, rows, "ll" + "r" * 9),
            "",
        ]
    )


def run_safety_benchmark(policy, out_dir, n: int = 2000) -> dict:
    """The three generators on ``n`` scenes per set, printed and written as safety_<date>_<machine>.*"""
    rl = TrajectoryGenerator.load(policy)
    cfftg = CFFTG(rl.config)
    margin, tol = rl.config.env.min_clearance, rl.config.env.backward_tolerance
    rows, payload = (
        [],
        {
            "policy": str(policy),
            "margin_m": margin,
            "backward_tolerance_m": tol,
            "dense_factor": FACTOR,
            "sets": {},
        },
    )
    for name, unseen in ((THESIS_FIVE, False), (SHAPES, True)):
        sc = safety_scenarios(rl.config, n, unseen=unseen)
        kw = batch_options(sc)
        obs = [s.obstacle for s in sc]
        out = {}
        for gname, make in (
            ("rl", lambda: rl.generate_batch(obs, fallback=None, **kw)),
            ("rl+cfftg", lambda: rl.generate_batch(obs, fallback="cfftg", **kw)),
            ("cfftg", lambda: cfftg.generate_batch(obs, **kw)),
        ):
            t0 = time.perf_counter()
            b = make()
            r = out[gname] = generator_figures(b, cfftg, margin, tol, time.perf_counter() - t0)
            rows.append((name, gname, *_cells(r)))
        payload["sets"][name] = out
    info = machine_info()
    payload["machine"] = info
    md = markdown(policy, margin, tol, info, rows)
    paths = write_result("safety", payload, md, out_dir)
    print(md)
    print("wrote", *paths)
    return payload
