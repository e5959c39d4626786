"""Walks over drawn courses (``jaxexo bench``'s ``course`` part): RL alone against CFFTG on the same
footholds, checked independently of the planner. Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from jaxexo.summary import Summary
from jaxexo.summary import table as md_table

RANDOM = "random_profile"
LENGTH = (3.0, 8.0)  # m
OBSTACLES = (2, 8)
START_FLAT = (0.9, 1.3)  # m of floor before the first obstacle and after the last
GAP = (0.45, 1.4)  # m of floor between obstacles
REFERENCE_COURSES = 10  # courses whose first steps are also timed as single swings


def random_profile(rng: np.random.Generator) -> np.ndarray:
    """A random ground obstacle (n, 2) in its own frame (y from 0): 3-7 raised vertices between floor ends,
    8-36 cm wide and 4-25 cm high (the training families' range, any polyline shape)."""
    w = rng.uniform(0.08, 0.36)
    h = rng.uniform(0.04, 0.25)
    k = int(rng.integers(3, 8))
    y = np.sort(rng.uniform(0.0, w, k))
    z = rng.uniform(0.15, 1.0, k) * h
    z[int(rng.integers(k))] = h
    return np.concatenate([[[0.0, 0.0]], np.column_stack([y, z]), [[w, 0.0]]])


def family_profile(name: str, rng: np.random.Generator) -> np.ndarray:
    """One obstacle of a terrain family (n, 2), in its own frame shifted to start at y = 0."""
    from jaxexo.physics import terrain

    u = rng.random((1, terrain.D_MAX), dtype=np.float32)
    out, w, _ = terrain.one_family_outline(np, name, u)
    pts = terrain.unpad(np.asarray(out[0], np.float64)).copy()
    pts[:, 0] += 0.5 * float(w[0])
    return pts


def draw_course(rng: np.random.Generator) -> tuple[np.ndarray, list[str]]:
    """(terrain points (n, 2), the obstacles' kinds): LENGTH long with OBSTACLES obstacles, each from a
    held-out family or a random profile, GAP of floor between them (fewer obstacles when they do not fit)."""
    from jaxexo.physics import terrain

    kinds = (*terrain.HELD_OUT_FAMILIES, RANDOM)
    length = rng.uniform(*LENGTH)
    k = int(rng.integers(OBSTACLES[0], OBSTACLES[1] + 1))
    names = [kinds[int(rng.integers(len(kinds)))] for _ in range(k)]
    shapes = [random_profile(rng) if n == RANDOM else family_profile(n, rng) for n in names]
    pre, post = rng.uniform(*START_FLAT), rng.uniform(*START_FLAT)
    gaps = rng.uniform(*GAP, k)
    while (
        k > OBSTACLES[0]
        and pre + post + sum(s[-1, 0] for s in shapes) + gaps[: k - 1].sum() > length
    ):
        k -= 1
        shapes, names = shapes[:k], names[:k]
    pts, y = [[0.0, 0.0]], pre
    for i, s in enumerate(shapes):
        pts.extend((s + [y, 0.0]).tolist())
        y += s[-1, 0] + (gaps[i] if i < k - 1 else 0.0)
    pts.append([max(length, y + post), 0.0])
    return np.asarray(pts), names


def _flat(ter, y0: float, y1: float) -> bool:
    ys = np.concatenate([np.linspace(y0, y1, 100), ter.y[(ter.y >= y0) & (ter.y <= y1)]])
    return bool(np.all(np.interp(ys, ter.y, ter.z) == 0.0))


def independent_checks(course, min_clearance: float) -> dict:
    """Checks of a walk from its exported table and the terrain alone (module docstring)."""
    from jaxexo.course import WALK_COLUMNS, obstacles_of
    from jaxexo.physics import geometry

    t = course.samples
    foot = course.steps[0].trajectory.toe[0, 0] - course.steps[0].trajectory.heel[0, 0]
    landings_ok = True
    for st in course.steps:
        row = t[int(np.argmin(np.abs(t[:, 0] - st.end_s)))]
        y, z = (
            row[WALK_COLUMNS.index(f"{st.leg}_heel_y_m")],
            row[WALK_COLUMNS.index(f"{st.leg}_heel_z_m")],
        )
        landings_ok &= z == 0.0 and _flat(
            course.terrain, y - min_clearance, y + foot + min_clearance
        )
    lowest = math.inf
    for ob in obstacles_of(course.terrain):
        for leg in ("left", "right"):
            heel = t[
                :, [WALK_COLUMNS.index(f"{leg}_heel_y_m"), WALK_COLUMNS.index(f"{leg}_heel_z_m")]
            ]
            near = (heel[:, 0] + foot >= ob[0, 0] - 0.1) & (heel[:, 0] <= ob[-1, 0] + 0.1)
            if near.any():
                lowest = min(lowest, float(geometry.foot_clearance(np, heel[near], foot, ob).min()))
    dt = 1.0 / course.rate
    q = t[
        :,
        [
            WALK_COLUMNS.index(f"{j}_rad")
            for j in ("hip_left", "knee_left", "hip_right", "knee_right")
        ],
    ]
    v = np.abs(np.diff(q, axis=0)) / dt
    a = np.abs(np.diff(q, n=2, axis=0)) / dt**2
    lim_v, lim_a = np.asarray(course.limits.velocity), np.asarray(course.limits.acceleration)
    uniform = bool(np.allclose(np.diff(t[:, 0]), dt, atol=1e-6))
    return {
        "landings_ok": bool(landings_ok),
        "min_sample_clearance_m": lowest,
        "uniform_time": uniform,
        "max_joint_step_rad": float(np.abs(np.diff(q, axis=0)).max()),
        "velocity_ratio": float((v / lim_v).max()),
        "acceleration_ratio": float((a / lim_a).max()),
        "within_limits": bool(np.all(v <= lim_v * (1 + 1e-3)) and np.all(a <= lim_a * (1 + 1e-3))),
    }


def _one_swing_seconds(gen, course, k: int) -> float:
    """Seconds to plan step k of ``course`` alone: the RL generator's swing and its device timing."""
    import dataclasses

    from jaxexo.inference import time_swing

    st = course.steps[k]
    ob = st.trajectory.scene.obstacle
    local = dataclasses.replace(ob, center_y=ob.center_y - st.start_y)  # planned in its own frame
    t0 = time.process_time()
    traj = gen.generate(
        local,
        pivot_y=st.pivot_y - st.start_y,
        start_y=0.0,
        step_length=st.goal_y - st.start_y,
        fallback=None,
    )
    time_swing(traj, gen.config, rate=course.rate)
    return time.process_time() - t0


def run_course_benchmark(
    policy,
    out_dir=None,
    n: int = 200,
    seed: int = 0,
    progress=print,
    name: str = "course",
    log=None,
) -> dict:
    """Plan ``n`` drawn courses with RL alone and with CFFTG, check them and write
    ``<name>_<date>_<machine>.json/.md`` to ``out_dir`` (when given). ``log``: a JSON-lines file that
    gets each course's row as it is done (``summarize_log`` summarises an interrupted run). Returns
    the figures."""
    from jaxexo.baselines import CFFTG
    from jaxexo.course import CourseError, footholds, plan_course
    from jaxexo.inference import Terrain, TrajectoryGenerator

    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n: the number of courses must be an integer >= 1, got {n!r}")
    gen = TrajectoryGenerator.load(policy)
    cfftg = CFFTG(gen.config)
    rng = np.random.default_rng(seed)
    rows, refused = [], []
    for i in range(n):
        pts, kinds = draw_course(rng)
        ter = Terrain.from_points(pts, source=f"course {i}")
        t0 = time.process_time()
        try:
            fh = footholds(ter, gen.config)
        except CourseError as e:
            refused.append(
                {
                    "course": i,
                    "kinds": kinds,
                    "length_m": float(pts[-1, 0]),
                    "message": str(e),
                    "seconds": time.process_time() - t0,
                }
            )
            _log(log, {"refused": refused[-1]})
            continue
        foothold_s = time.process_time() - t0
        row = {
            "course": i,
            "kinds": kinds,
            "length_m": float(pts[-1, 0]),
            "obstacles": len(kinds),
            "steps": len(fh),
            "footholds_s": foothold_s,
        }
        for label, g, kw in (("rl", gen, {"fallback": None}), ("cfftg", cfftg, {})):
            t0 = time.process_time()
            c = plan_course(g, ter, **kw)
            cpu = time.process_time() - t0
            assert c.footholds == fh  # the same footholds for both
            r = {
                "ok": c.ok,
                "duration_s": c.duration if c.ok else None,
                "plan_wall_s": c.plan_seconds,
                "plan_s": cpu,
                "plan_s_per_step": cpu / len(c.steps),
                "failed_step": None,
                "reasons": list(c.reasons),
            }
            if not c.ok:
                bad = [s for s in c.steps if not s.ok]
                r["failed_step"] = bad[0].index + 1 if bad else None
            else:
                r.update(independent_checks(c, gen.config.env.min_clearance))
            if label == "rl" and len(rows) < REFERENCE_COURSES and c.ok:
                one = [_one_swing_seconds(gen, c, k) for k in range(min(3, len(c.steps)))]
                r["one_swing_s"] = Summary.of(one).median
            row[label] = r
        rows.append(row)
        _log(log, {"row": row})
        if progress and (i + 1) % 10 == 0:
            progress(
                f"course {i + 1}/{n}: {sum(r['rl']['ok'] for r in rows)}/{len(rows)} RL-alone walks ok"
            )
    res = summarize(rows, refused, n, seed)
    if out_dir is not None:
        from jaxexo.evaluation.machine import write_result

        write_result(name, res, markdown(res), Path(out_dir))
    return res


def _log(path, entry: dict) -> None:
    if path is not None:
        import json

        from jaxexo.storage.atomic import append_line

        append_line(path, json.dumps(entry) + "\n")


def summarize_log(path, seed: int = 0) -> dict:
    """``summarize`` of the courses a (possibly interrupted) run logged to ``path``."""
    import json

    rows, refused = [], []
    for line in Path(path).read_text().splitlines():
        e = json.loads(line)
        (rows if "row" in e else refused).append(e.get("row", e.get("refused")))
    return summarize(rows, refused, len(rows) + len(refused), seed)


def _median(xs: list) -> float | None:
    """The median of ``xs``, None (JSON's null) when there is none."""
    return Summary.of(xs).median if xs else None


def summarize(rows, refused, n, seed) -> dict:
    def share(label, key="ok"):
        return sum(bool(r[label].get(key)) for r in rows) / len(rows) if rows else float("nan")

    both = [r for r in rows if r["rl"]["ok"] and r["cfftg"]["ok"]]
    ratio = [r["rl"]["duration_s"] / r["cfftg"]["duration_s"] for r in both]
    per_step = [r["rl"]["plan_s_per_step"] for r in rows if r["rl"]["ok"]]
    ref = [
        (r["rl"]["plan_s_per_step"], r["rl"]["one_swing_s"])
        for r in rows
        if "one_swing_s" in r["rl"]
    ]
    checks = {}
    for label in ("rl", "cfftg"):
        ok = [r[label] for r in rows if r[label]["ok"]]
        checks[label] = {
            "walks": len(ok),
            "landings_ok": sum(c["landings_ok"] for c in ok),
            "within_limits": sum(c["within_limits"] for c in ok),
            "uniform_time": sum(c["uniform_time"] for c in ok),
            "min_sample_clearance_m": min((c["min_sample_clearance_m"] for c in ok), default=None),
            "max_joint_step_rad": max((c["max_joint_step_rad"] for c in ok), default=None),
            "max_velocity_ratio": max((c["velocity_ratio"] for c in ok), default=None),
            "max_acceleration_ratio": max((c["acceleration_ratio"] for c in ok), default=None),
        }
    return {
        "courses_drawn": n,
        "seed": seed,
        "planned": len(rows),
        "refused": len(refused),
        "refusals": refused,
        "refusal_seconds_max": max((r["seconds"] for r in refused), default=None),
        "rl_alone_success": share("rl"),
        "cfftg_success": share("cfftg"),
        "rl_failed_courses": [
            {
                "course": r["course"],
                "step": r["rl"]["failed_step"],
                "reasons": r["rl"]["reasons"][:1],
            }
            for r in rows
            if not r["rl"]["ok"]
        ],
        "steps_median": _median([r["steps"] for r in rows]),
        "duration_s_median": {
            "rl": _median([r["rl"]["duration_s"] for r in both]),
            "cfftg": _median([r["cfftg"]["duration_s"] for r in both]),
        },
        "duration_ratio_rl_over_cfftg": {
            "median": _median(ratio),
            "max": Summary.of(ratio).max if ratio else None,
            "n": len(ratio),
        },
        "plan_s_per_step_median": _median(per_step),
        "one_swing_s_median": _median([b for _, b in ref]),
        "per_step_over_one_swing_median": _median([a / b for a, b in ref]),
        "reference_courses": len(ref),
        "checks": checks,
        "courses": rows,
    }


def _table_rows(res: dict) -> list[tuple]:
    """The summary table's rows: (figure, RL alone, CFFTG, target)."""
    d, rr = res["duration_s_median"], res["duration_ratio_rl_over_cfftg"]
    rows = [
        (
            "courses with every swing safe (strict verdict, 2 cm)",
            *(_pct(res[k]) for k in ("rl_alone_success", "cfftg_success")),
            "RL >= 99 %",
        ),
        (
            f"walk duration at the device limits, median (both ok, n = {rr['n']})",
            *(_num(d[g], "{:.2f} s") for g in ("rl", "cfftg")),
            "RL <= CFFTG",
        ),
        (
            "RL / CFFTG duration per course: median, max",
            f"{_num(rr['median'])}, {_num(rr['max'])}",
            "",
            "<= 1",
        ),
        (
            "planning CPU time per step (footholds and timing included), median",
            f"{_num(res['plan_s_per_step_median'])} s",
            "",
            "",
        ),
        (
            f"one swing alone (generate + time_swing), CPU, median of {res['reference_courses']} "
            "courses' first steps",
            f"{_num(res['one_swing_s_median'])} s",
            "",
            "",
        ),
        (
            "per step / one swing, median",
            _num(res["per_step_over_one_swing_median"], "{:.2f}x"),
            "",
            "<= 1.5x",
        ),
    ]
    for label in ("rl", "cfftg"):
        c = res["checks"][label]
        rows.append(
            (
                f"{label}: walks checked independently: landings on flat ground, within the limits "
                "(finite differences), uniform time",
                f"{c['landings_ok']}, {c['within_limits']}, {c['uniform_time']} of {c['walks']}",
                "",
                "all",
            )
        )
        rows.append(
            (
                f"{label}: least foot clearance at the samples; largest joint step per sample; peak "
                "velocity and acceleration / limit",
                f"{_num(c['min_sample_clearance_m'], '{:.4f} m')}; "
                f"{_num(c['max_joint_step_rad'], '{:.4f} rad')}; {_num(c['max_velocity_ratio'])}, "
                f"{_num(c['max_acceleration_ratio'])}",
                "",
                ">= 0.02 m; -; <= 1",
            )
        )
    return rows


def _pct(x) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{100 * x:.1f} %"


def _num(x, fmt="{:.3f}") -> str:
    return "-" if x is None else fmt.format(x)


def markdown(res: dict) -> str:
    lines = [
        "# Walks over courses: RL alone against CFFTG on the same footholds",
        "",
        f"{res['courses_drawn']} courses drawn (seed {res['seed']}; 3-8 m, 2-8 obstacles from the held-out families "
        f"and random profiles); {res['planned']} planned, {res['refused']} refused before any swing "
        f"(slowest refusal {_num(res['refusal_seconds_max'])} s CPU). Median {_num(res['steps_median'], '{:.0f}')} swings "
        "per course.",
        "",
        *md_table(("figure", "RL alone", "CFFTG", "target"), _table_rows(res), "llll"),
    ]
    if res["rl_failed_courses"]:
        lines += ["", "RL-alone failures (course, step, first reason):", ""]
        lines += [
            f"- course {f['course']}, step {f['step']}: {'; '.join(f['reasons'])[:300]}"
            for f in res["rl_failed_courses"][:20]
        ]
    if res["refusals"]:
        lines += ["", "Refusals (first 10):", ""]
        lines += [
            f"- course {r['course']} ({r['length_m']:.2f} m, {', '.join(r['kinds'])}): {r['message']}"
            for r in res["refusals"][:10]
        ]
    return "\n".join(lines) + "\n"


PIVOT_PLACES = ("agent", "before", "after", "goal")


def run_pivot_benchmark(
    policy, out_dir=None, n: int = 60, seed: int = 0, name: str = "course-pivots"
) -> dict:
    """Does the policy handle the pivots a course produces? RL alone on ``n`` scenes per terrain
    family (held-out and training) with the stance heel at the swing's start (``agent``, the
    training's own condition), on the floor before the obstacle (the first leg over it), after it
    (the second leg: the stance foot ahead of the obstacle, never drawn in training) and at the goal
    (the swing that brings the feet together). Writes ``<name>_<date>_<machine>.json/.md``."""
    from jaxexo.course import FootholdRules
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.physics import terrain

    gen = TrajectoryGenerator.load(policy)
    r = FootholdRules.of(gen.config)
    room = r.stand + r.tolerance
    rng = np.random.default_rng(seed)
    table = {}
    for fam in terrain.HELD_OUT_FAMILIES + terrain.TRAIN_FAMILIES:
        u = rng.random((n, terrain.D_MAX), dtype=np.float32)
        out, w, _ = terrain.one_family_outline(np, fam, u)
        obs, piv, steps, places = [], [], [], []
        for i in range(n):
            wi = float(w[i])
            s = min(r.hi, max(r.lo, r.foot + 2 * room + wi) + rng.random() * 0.15)
            c = r.foot + room + 0.5 * wi + rng.random() * max(0.0, s - 2 * room - wi - r.foot)
            o = terrain.to_obstacle(out[i], c)
            before = rng.random() * max(0.0, o.left - r.foot - room)
            after = o.right + room + rng.random() * max(0.0, s - o.right - room)
            for place, p in zip(PIVOT_PLACES, (0.0, before, after, s)):
                obs.append(o)
                piv.append(p)
                steps.append(s)
                places.append(place)
        ok = gen.generate_batch(obs, pivot_y=piv, start_y=0.0, step_length=steps, fallback=None).ok
        places = np.array(places)
        table[fam] = {
            p: [int(ok[places == p].sum()), int((places == p).sum())] for p in PIVOT_PLACES
        }
    total = {
        p: [sum(t[p][0] for t in table.values()), sum(t[p][1] for t in table.values())]
        for p in PIVOT_PLACES
    }
    res = {"n_per_family": n, "seed": seed, "by_family": table, "total": total}
    if out_dir is not None:
        from jaxexo.evaluation.machine import write_result

        lines = [
            "# The pivots a course produces: RL alone, safe swings (strict verdict, 2 cm)",
            "",
            f"{n} scenes per family; the same obstacle and step with the stance heel at each place.",
            "",
            *md_table(
                ("family", *PIVOT_PLACES),
                [
                    (fam, *(f"{a}/{b}" for a, b in (t[p] for p in PIVOT_PLACES)))
                    for fam, t in [*table.items(), ("all", total)]
                ],
                "l" * (len(PIVOT_PLACES) + 1),
            ),
        ]
        write_result(name, res, "\n".join(lines) + "\n", Path(out_dir))
    return res


def run_swing_breakdown(
    policy, out_dir=None, n: int = 30, seed: int = 0, name: str = "course-swings"
) -> dict:
    """Where a walk's time goes, swing by swing: on the first ``n`` drawn courses that both generators
    walk safely (RL alone, CFFTG on the same footholds), each RL swing's timed duration over CFFTG's
    and both heels' lift, split into swings over flat floor (the virtual FLAT_OBSTACLE) and over
    obstacles, and the RL heel's travel along the floor at the end of its swings (within 1 mm of it)."""
    from jaxexo.baselines.cfftg import CFFTG
    from jaxexo.course import CourseError, plan_course
    from jaxexo.inference import TrajectoryGenerator

    rl = TrajectoryGenerator.load(policy)
    cf = CFFTG(rl.config)
    rng = np.random.default_rng(seed)
    ratio, lift, slide = {True: [], False: []}, {True: [], False: []}, []
    walked = 0
    while walked < n:
        points, _ = draw_course(rng)
        try:
            a, b = plan_course(rl, points, fallback=None), plan_course(cf, points)
        except CourseError:
            continue
        if not (a.ok and b.ok):
            continue
        walked += 1
        for sa, sb in zip(a.steps, b.steps):
            ratio[sa.flat].append(sa.timed.duration / sb.timed.duration)
            lift[sa.flat].append(
                (float(sa.trajectory.heel[:, 1].max()), float(sb.trajectory.heel[:, 1].max()))
            )
            h = np.asarray(sa.trajectory.heel)
            last_up = len(h) - 1 - int(np.argmin(h[::-1, 1] <= 1e-3))
            slide.append(float(h[-1, 0] - h[last_up, 0]))
    rows = {
        ("flat" if f else "obstacle"): {
            "swings": len(ratio[f]),
            "duration_ratio_median": Summary.of(ratio[f]).median,
            "duration_ratio_mean": Summary.of(ratio[f]).mean,
            "lift_median_m": {
                "rl": Summary.of([x[0] for x in lift[f]]).median,
                "cfftg": Summary.of([x[1] for x in lift[f]]).median,
            },
        }
        for f in (True, False)
    }
    res = {
        "courses": n,
        "seed": seed,
        "by_kind": rows,
        "rl_floor_travel_m": {
            "median": Summary.of(slide).median,
            "p95": Summary.of(slide).p95,
        },
    }
    if out_dir is not None:
        from jaxexo.evaluation.machine import write_result

        lines = [
            "# A walk's swings: RL alone against CFFTG on the same footholds",
            "",
            f"The first {n} drawn courses (seed {seed}) that both walk safely.",
            "",
            *md_table(
                (
                    "swings",
                    "n",
                    "RL / CFFTG duration, median / mean",
                    "heel lift median, RL / CFFTG cm",
                ),
                [
                    (
                        k,
                        str(r["swings"]),
                        f"{r['duration_ratio_median']:.3f} / {r['duration_ratio_mean']:.3f}",
                        f"{100 * r['lift_median_m']['rl']:.1f} / {100 * r['lift_median_m']['cfftg']:.1f}",
                    )
                    for k, r in rows.items()
                ],
            ),
        ]
        ft = res["rl_floor_travel_m"]
        lines += [
            "",
            f"RL heel travel along the floor at the end of a swing: median {1000 * ft['median']:.1f} mm, "
            f"p95 {1000 * ft['p95']:.1f} mm.",
            "",
        ]
        write_result(name, res, "\n".join(lines), Path(out_dir))
    return res
