"""MuJoCo replay benchmark: every swing of the safety sets replayed kinematically and driven
(jaxexo.sim.replay). Run by benchmarks/bench_replay.py; method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import time

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.evaluation.machine import machine_info, write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics import geometry
from jaxexo.physics.scenarios import batch_options
from jaxexo.sim.replay import (
    Legs,
    brute_force_distance,
    driven_replay,
    kinematic_replay,
    summarize_driven,
    summarize_kinematic,
)
from jaxexo.summary import Summary, table
from jaxexo.swing.timing import DeviceLimits, time_swings

from benchlib.scenes import safety_sets


def replay_set(sc, rl, cfftg, config, rate: float, driven: bool) -> dict:
    kw = batch_options(sc)
    obs = [s.obstacle for s in sc]
    default = DeviceLimits.from_config(config)
    out = {}
    legs_cache = {}
    for gname, make in (
        ("rl", lambda: rl.generate_batch(obs, fallback=None, **kw)),
        ("cfftg", lambda: cfftg.generate_batch(obs, **kw)),
    ):
        batch = make()
        t0 = time.perf_counter()
        timed = time_swings(batch, config, rate=rate)
        t_timing = time.perf_counter() - t0
        kin, drv, drv_servo, build_s = [], [], [], []
        disagree, violations = [], []
        for i, ts in enumerate(timed):
            if i not in legs_cache:
                t1 = time.perf_counter()
                legs_cache[i] = Legs(config, ts.scene)
                build_s.append(time.perf_counter() - t1)
            legs = legs_cache[i]
            k = kinematic_replay(ts, config, legs=legs)
            kin.append(k)
            s = k.max_disagreement_sample
            if s >= 0:
                jx = float(
                    geometry.foot_clearance(
                        np, np.asarray(ts.heel[s]), config.kinematics.foot_length, ts.scene.outline
                    )
                )
                legs.set_pose(legs.qpos(ts.joint_angles[s]))
                mj = legs.foot_distance()
                bf = brute_force_distance(
                    ts.heel[s], config.kinematics.foot_length, ts.scene.outline
                )
                disagree.append({"jaxexo": jx, "mujoco": mj, "brute": bf})
            if k.flagged_ok_but_within_margin:
                # The third look at MuJoCo's closest pose: the brute-force distance of that heel.
                brute = brute_force_distance(
                    k.mujoco_min_heel, config.kinematics.foot_length, ts.scene.outline
                )
                violations.append({**k.to_dict(), "brute_at_mujoco_min_m": brute})
            if driven and ts.ok:
                drv.append(driven_replay(ts, config, legs=legs, limits=default, controller="pd_ff"))
                drv_servo.append(
                    driven_replay(ts, config, legs=legs, limits=default, controller="servo")
                )
        ok = np.array([t.ok for t in timed])
        r = {
            "n": len(timed),
            "flagged_ok": int(ok.sum()),
            "timing_seconds": t_timing,
            "model_build_ms_median": 1e3 * Summary.of(build_s).median if build_s else None,
            "kinematic": {
                **summarize_kinematic(kin).to_dict(),
                "violations": violations,
            },
        }
        if disagree:
            w = max(disagree, key=lambda x: abs(x["jaxexo"] - x["mujoco"]))
            r["kinematic"]["worst_disagreement"] = {
                **w,
                "nearer_brute": "jaxexo"
                if abs(w["jaxexo"] - w["brute"]) <= abs(w["mujoco"] - w["brute"])
                else "mujoco",
            }
            r["kinematic"]["brute_nearer_jaxexo_share"] = float(
                np.mean(
                    [
                        abs(x["jaxexo"] - x["brute"]) <= abs(x["mujoco"] - x["brute"])
                        for x in disagree
                    ]
                )
            )
        for name, rows in (("driven", drv), ("driven_servo", drv_servo)):
            if rows:
                r[name] = summarize_driven(rows).to_dict()
        out[gname] = r
        print(
            f"[{time.strftime('%H:%M:%S')}]",
            gname,
            {k: v for k, v in r.items() if k != "kinematic"},
            {k: v for k, v in r["kinematic"].items() if k != "violations"},
            flush=True,
        )
    return out


def _mm(x):
    return "-" if x is None or x != x else f"{1000 * x:.1f}"


def markdown(payload: dict, policy, n: int, rate: float, margin: float) -> str:
    rows_k, rows_d = [], []
    for name, gens in payload["sets"].items():
        for g, r in gens.items():
            k = r["kinematic"]
            w = k.get("worst_disagreement", {})
            rows_k.append(
                (
                    *(
                        name,
                        g,
                        str(r["n"]),
                        str(r["flagged_ok"]),
                        str(k["flagged_ok_within_margin"]),
                    ),
                    _mm(k["min_mujoco_distance_of_ok_m"]),
                    _mm(k["min_mujoco_minus_guaranteed_of_ok_m"]),
                    f"{1e6 * k['max_disagreement_m']:.3f}",
                    w.get("nearer_brute", "-"),
                    f"{1e3 * k['seconds_median']:.1f}",
                )
            )
            for lim in ("driven", "driven_servo"):
                if lim in r:
                    d = r[lim]
                    rows_d.append((name, g, "pd_ff" if lim == "driven" else "servo", *_driven(d)))
    return "\n".join(
        [
            "# MuJoCo replay benchmark",
            "",
            f"Policy `{policy}`; {n} scenes per set requested (held-out families: whole cells); control rate "
            f"{rate:g} Hz; margin env.min_clearance = {100 * margin:.1f} cm; MuJoCo "
            f"{__import__('mujoco').__version__}; {payload['seconds']:.0f} s in all.",
            "",
            "## Kinematic replay (MuJoCo's mj_geomDistance at every control sample and 3 poses between)",
            "",
            *table(KINEMATIC, rows_k, "ll" + "r" * 6 + "lr"),
            "",
            "## Driven replay of the swings flagged ok (setpoints within the [device] limits)",
            "",
            "Swings timed for the [device] limits (less the tracking headroom), driven at them by two controllers on the "
            "same setpoints: pd_ff, PD with inverse-dynamics feed-forward; servo, stiff position servos. Heel error "
            "off the floor: at the samples where the swing's heel is more than 1 mm above the floor.",
            "",
            *table(DRIVEN, rows_d, "lll" + "r" * 9),
            "",
        ]
    )


KINEMATIC = (
    *("scenes", "generator", "n", "flagged ok", "flagged ok, within margin in MuJoCo"),
    *("min MuJoCo distance of ok, mm", "min (MuJoCo - jaxexo guaranteed), mm"),
    *("max disagreement at the samples, um", "nearer the brute force", "replay ms (median)"),
)
DRIVEN = (
    *("scenes", "generator", "controller", "n", "heel error p95 / max, mm"),
    *("heel error off the floor p95, mm", "toe error p95 / max, mm", "contacts", "within margin"),
    *("min distance, mm", "saturated", "replay ms (median)"),
)


def _driven(d: dict) -> tuple[str, ...]:
    """A driven replay's figures, the table's cells after the set, generator and controller."""
    return (
        str(d["n"]),
        f"{_mm(d['heel_error_p95_m'])} / {_mm(d['heel_error_max_m'])}",
        _mm(d["heel_error_airborne_p95_m"]),
        f"{_mm(d['toe_error_p95_m'])} / {_mm(d['toe_error_max_m'])}",
        *(str(d[k]) for k in ("contacts", "within_margin")),
        _mm(d["min_distance_m"]),
        str(d["saturated"]),
        f"{1e3 * d['seconds_median']:.0f}",
    )


def run_replay_benchmark(
    policy,
    out_dir,
    n: int = 1000,
    rate: float | None = None,
    driven: bool = True,
    name: str = "replay",
) -> dict:
    """Both generators' swings on ``n`` scenes per set replayed at ``rate`` Hz (default: the config's
    control rate), printed and written as <name>_<date>_<machine>.{json,md}."""
    rl = TrajectoryGenerator.load(policy)
    config = rl.config
    cfftg = CFFTG(config)
    rate = config.device.control_rate if rate is None else rate
    payload = {
        "policy": str(policy),
        "n_per_set": n,
        "rate_hz": rate,
        "margin_m": config.env.min_clearance,
        "sets": {},
    }
    t0 = time.perf_counter()
    for set_name, sc in safety_sets(config, n, pick=False).items():
        print(set_name, len(sc), flush=True)
        payload["sets"][set_name] = replay_set(sc, rl, cfftg, config, rate, driven)
    payload["seconds"] = time.perf_counter() - t0
    payload["machine"] = machine_info()
    md = markdown(payload, policy, n, rate, config.env.min_clearance)
    paths = write_result(name, payload, md, out_dir)
    print(md)
    print("wrote", *paths)
    return payload
