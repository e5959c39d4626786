"""Tracking-room study: the [device] tracking headroom and jerk limit chosen by measurement. RL
(alone) and CFFTG swings on unseen shapes are timed with each (headroom, jerk) setting and driven in
MuJoCo at the full device limits by the PD with inverse-dynamics feed-forward (jaxexo.sim.replay):
swing duration, setpoints clipped (saturation), heel tracking error off the floor, and swings flagged
ok that come within the margin once driven.

Writes benchmarks/results/tracking_<date>_<machine>.{json,md}."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from jaxexo.summary import Summary, table

SETTINGS = (
    (0.0, False),
    (0.05, False),
    (0.1, False),
    (0.1, True),
    (0.2, True),
)  # (headroom, jerk limit on)


HEADER = (
    *("headroom", "jerk limit", "generator", "ok", "duration median / p95 s", "setpoints clipped"),
    *("heel error off the floor p95 / max mm", "within 2 cm driven", "min distance mm"),
)


def _cells(r: dict) -> tuple[str, ...]:
    """One setting's and generator's row."""
    air = (1e3 * r["heel_error_airborne_p95_m"], 1e3 * r["heel_error_airborne_max_m"])
    return (
        *(f"{r['headroom']:.2f}", "on" if r["jerk"] else "off", r["generator"], str(r["ok"])),
        f"{r['duration_median_s']:.3f} / {r['duration_p95_s']:.3f}",
        str(r["saturated"]),
        f"{air[0]:.1f} / {air[1]:.1f}",
        *(str(r["within_margin"]), f"{1e3 * r['min_distance_m']:.1f}"),
    )


def run_tracking_benchmark(
    policy: str | Path, out_dir: str | Path, n: int = 100, rate: float = 100.0
) -> dict:
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.machine import machine_info, write_result
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.inference.scenarios import safety_scenarios
    from jaxexo.physics.scenarios import batch_options
    from jaxexo.sim.replay import Legs, driven_replay
    from jaxexo.swing.timing import DeviceLimits, time_swings

    rl = TrajectoryGenerator.load(policy)
    cfg = rl.config
    sc = safety_scenarios(cfg, n, unseen=True)
    kw = batch_options(sc)
    obs = [s.obstacle for s in sc]
    batches = {
        "rl": rl.generate_batch(obs, fallback=None, **kw),
        "cfftg": CFFTG(cfg).generate_batch(obs, **kw),
    }
    device = DeviceLimits.from_config(cfg)
    legs = {}
    rows = []
    t0 = time.perf_counter()
    for headroom, jerk in SETTINGS:
        lim = dataclasses.replace(device, headroom=headroom, jerk=device.jerk if jerk else None)
        for g, batch in batches.items():
            timed = time_swings(batch, cfg, rate=rate, limits=lim)
            drv = []
            for i, ts in enumerate(timed):
                if ts.ok:
                    leg = legs.setdefault(i, Legs(cfg, ts.scene))
                    # Driven at the device's full limits: the headroom is the controller's room.
                    drv.append(
                        driven_replay(
                            ts, cfg, limits=dataclasses.replace(lim, headroom=0.0), legs=leg
                        )
                    )
            fig = [d.figures for d in drv]
            air = Summary.of([f.heel_error_airborne_max_m for f in fig])
            span = Summary.of([t.duration for t in timed])
            dist = np.array([f.mujoco_min_distance_m for f in fig])
            rows.append(
                {
                    "headroom": headroom,
                    "jerk": list(device.jerk) if jerk else None,
                    "generator": g,
                    "n": len(timed),
                    "ok": len(drv),
                    "duration_median_s": span.median,
                    "duration_p95_s": span.p95,
                    "saturated": int(sum(f.saturated for f in fig)),
                    "heel_error_airborne_p95_m": air.p95,
                    "heel_error_airborne_max_m": air.max,
                    "within_margin": int(np.sum(dist < cfg.env.min_clearance)),
                    "min_distance_m": float(dist.min()),
                }
            )
            print(rows[-1], flush=True)
    payload = {
        "policy": str(policy),
        "rate_hz": rate,
        "n": n,
        "rows": rows,
        "seconds": time.perf_counter() - t0,
        "machine": machine_info(),
    }
    md = "\n".join(
        [
            "# Tracking room: headroom and jerk limit, driven by PD + inverse-dynamics feed-forward",
            "",
            f"Policy `{policy}`; {n} unseen-shape scenes; {rate:g} Hz; swings timed with each setting, driven in "
            "MuJoCo at the full [device] limits; figures over the swings flagged ok.",
            "",
            *table(HEADER, map(_cells, rows), "rll" + "r" * 6),
            "",
            f"Machine: {payload['machine']['cpu']}, {payload['machine']['cores']} cores; {payload['seconds']:.0f} s.",
            "",
        ]
    )
    write_result("tracking", payload, md, out_dir)
    print(md)
    return payload
