"""``plan_course``: a walk over a course planned swing by swing with a generator and timed for the
device (jaxexo.course, 2. and 3.)."""

from __future__ import annotations

import dataclasses
import time as _time
from pathlib import Path

import numpy as np

from jaxexo.course.ground import (
    ROW_BYTES,
    CourseError,
    FootholdRules,
    check_double_support,
    check_number,
    check_walk_size,
    describe,
    flat_obstacle,
    obstacles_of,
    walk_size,
)
from jaxexo.course.placement import footholds
from jaxexo.course.record import JUNCTION_TOL, LEGS, WALK_COLUMNS, Course, CourseStep, walk_table
from jaxexo.physics import geometry
from jaxexo.storage.terrain_file import Terrain, read_terrain
from jaxexo.swing.trajectory import Trajectory, assemble


def _swing_obstacle(obs, start, goal, r: FootholdRules, terrain: Terrain):
    inside = [o for o in obs if o[0, 0] > start and o[-1, 0] < goal]
    if not inside:
        return flat_obstacle(start, goal, r.foot, r.stand), True
    try:
        return geometry.Obstacle.profile(np.concatenate(inside)), False
    except geometry.GeometryError as e:
        raise CourseError(_not_an_obstacle(terrain, inside, e)) from None


def _not_an_obstacle(terrain: Terrain, inside, e) -> str:
    """Why the terrain's obstacles between a swing's start and goal make no swing's obstacle, named
    by the file and the lines (points) of their profile above the floor."""
    pts = terrain.points
    first, last = inside[0][inside[0][:, 1] > 0][0], inside[-1][inside[-1][:, 1] > 0][-1]
    i = int(np.flatnonzero((pts == first).all(axis=1) & (terrain.z > 0))[0])
    j = int(np.flatnonzero((pts == last).all(axis=1) & (terrain.z > 0))[-1])
    span = terrain.place(i) + (f" to {terrain.where[j]}" if j != i and terrain.where else "")
    if last[0] == first[0]:
        return (
            f"{span}: {describe(inside[0])} rises and falls at one y = {first[0]:g} m (a vertical "
            "spike of no width); a swing's obstacle needs a width: give its top two y values"
        )
    return f"{span}: {', '.join(map(describe, inside))} make no swing's obstacle: {e}"


def _in_course(
    traj: Trajectory, gen, obstacle, start: float, pivot: float, goal: float
) -> Trajectory:
    """A swing planned in its own frame (start at y = 0) placed on the course at ``start`` and checked
    there again (trajectory.assemble: the same checks)."""
    shift = np.array([start, 0.0])
    scene = gen.scene(obstacle, pivot_y=pivot, start_y=start, step_length=goal - start)
    batch = assemble(
        traj.method,
        gen.sp,
        [scene],
        [traj.raw + shift],
        (traj.heel + shift)[None],
        [traj.smoothing],
        duration=float(traj.time[-1]),
        notes=[tuple(traj.notes)],
        deviation=[traj.checks.deviation],
    )
    return batch[0]


def _shifted(ob: geometry.Obstacle, dy: float) -> geometry.Obstacle:
    return dataclasses.replace(ob, center_y=ob.center_y + dy)


def _as_terrain(terrain) -> Terrain:
    if isinstance(terrain, Terrain):
        return terrain
    if isinstance(terrain, (str, Path)):
        return read_terrain(terrain)
    return Terrain.from_points(terrain)


def plan_course(
    generator,
    terrain,
    *,
    start_y: float | None = None,
    goal_y: float | None = None,
    steps: int | None = None,
    fallback: str | None = "cfftg",
    rate: float | None = None,
    limits=None,
    clearance: float | None = None,
    double_support: float = 0.0,
) -> Course:
    """Plan a walk over ``terrain`` (a Terrain, a terrain file's path or (y, z) points) with
    ``generator`` (a TrajectoryGenerator, or a CFFTG for its swings on the same footholds): the
    footholds (``footholds``), each swing (``fallback``: "cfftg" or None, the RL generator only),
    timed at the device ``limits`` (default: the config's [device]) and sampled at ``rate`` Hz
    (default: its control rate), with a ``double_support`` dwell (s) at each landing. Infeasible
    courses and bad options raise CourseError (TerrainFileError for bad points) before any swing is
    planned; a walk whose swings fail is returned with ``ok`` False and the reasons."""
    from jaxexo.baselines.cfftg import CFFTG
    from jaxexo.inference.generator import TrajectoryGenerator
    from jaxexo.swing.options import check_fallback
    from jaxexo.swing.timing import DeviceLimits, time_swings

    t0 = _time.perf_counter()
    if not isinstance(generator, (TrajectoryGenerator, CFFTG)):
        raise CourseError(
            f"generator: expected a TrajectoryGenerator or CFFTG, got {type(generator).__name__}"
        )
    config = generator.config
    rl = isinstance(generator, TrajectoryGenerator)
    fallback = check_fallback(fallback)
    terrain = _as_terrain(terrain)
    ds = check_double_support("double_support", double_support)
    limits = DeviceLimits.from_config(config) if limits is None else limits
    gen = generator.at_clearance(clearance)
    r = FootholdRules.of(config, clearance)
    _check_size(terrain, config, r, limits, rate, start_y, goal_y, steps, ds)
    plan = footholds(
        terrain, config, start_y=start_y, goal_y=goal_y, steps=steps, clearance=clearance
    )
    trajs, meta, stopped = _swings(gen, rl, fallback, plan, terrain, r)
    # A failed swing is not timed (its path may not be one a drive can follow).
    good = [t for t in trajs if t.ok]
    timed = time_swings(good, config, rate=rate, limits=limits, sp=gen.sp) if good else []
    rate = timed[0].rate if timed else float(config.device.control_rate if rate is None else rate)
    samples, spans, jump = walk_table(timed, meta, ds, rate)
    steps_out, reasons = _steps(trajs, meta, timed, spans, stopped, len(plan))
    if jump > JUNCTION_TOL:
        reasons.append(
            f"the joint angles jump by {jump:.2e} rad where one swing hands over to the next"
        )
    notes = tuple(
        f"step {s.index + 1}: {s.method}" for s in steps_out if s.method == "cfftg-fallback"
    )
    return Course(
        terrain,
        plan,
        tuple(steps_out),
        float(rate),
        limits,
        ds,
        "rl" if rl else "cfftg",
        samples,
        jump,
        tuple(reasons),
        _time.perf_counter() - t0,
        notes,
    )


# What the API's size refusal names (the command line names its options: jaxexo.cli.walk).
SIZE_NAMES = {"rate": "rate", "course": "goal_y, steps", "outputs": ""}


def _check_size(terrain, config, r, limits, rate, start_y, goal_y, steps, dwell) -> None:
    """The walk's size (``walk_size``) refused before any work where its samples would not fit
    (``check_walk_size``); the numbers it reads checked first, as the planning checks them."""
    from jaxexo.swing.timing import DeviceLimits, check_rate

    if not isinstance(limits, DeviceLimits):
        raise CourseError(f"limits: expected a DeviceLimits, got {type(limits).__name__}")
    size = walk_size(
        terrain,
        config,
        r,
        limits=limits,
        rate=None if rate is None else check_rate(rate),
        start_y=check_number("start_y", start_y),
        goal_y=check_number("goal_y", goal_y),
        steps=check_number("steps", steps, 1, integer=True),
        dwell=dwell,
    )
    check_walk_size(size, columns=len(WALK_COLUMNS), row_bytes=ROW_BYTES, names=SIZE_NAMES)


def _swings(gen, rl: bool, fallback, plan, terrain: Terrain, r: FootholdRules):
    """Each swing of the walk in order, until one fails: (trajectories, each swing's (index, leg,
    start, pivot, goal, landing, flat), the index of the failed swing or None)."""
    feet = [plan.start_y, plan.start_y]  # heel y of the left and right foot
    obs = obstacles_of(terrain)
    trajs, meta, stopped = [], [], None
    for k in range(len(plan)):
        leg = k % 2
        start, pivot, goal = feet[leg], feet[1 - leg], plan.landings[k]
        ob, flat = _swing_obstacle(obs, start, goal, r, terrain)
        # The policy observes absolute positions (it is trained with starts 0-12 cm): each swing is
        # planned in its own frame, starting at y = 0, and placed on the course after.
        kw = dict(pivot_y=pivot - start, start_y=0.0, step_length=goal - start)
        local = _shifted(ob, -start)
        traj = gen.generate(local, fallback=fallback, **kw) if rl else gen.generate(local, **kw)
        traj = _in_course(traj, gen, ob, start, pivot, goal)
        feet[leg] = float(traj.heel[-1, 0])
        trajs.append(traj)
        meta.append((k, LEGS[leg], start, pivot, goal, feet[leg], flat))
        if not traj.ok:
            stopped = k
            break
    return trajs, meta, stopped


def _steps(trajs, meta, timed, spans, stopped, n_planned: int):
    """The walk's steps (CourseStep, the swings not timed with no time of their own) and the reasons
    of those that failed, and of the steps not planned after a failed swing."""
    end = spans[-1][1] if spans else 0.0
    timed = timed + [None] * (len(trajs) - len(timed))
    spans = spans + [(end, end)] * (len(trajs) - len(spans))
    steps_out, reasons = [], []
    for (k, leg, start, pivot, goal, land, flat), traj, t, span in zip(meta, trajs, timed, spans):
        st = CourseStep(k, leg, start, pivot, goal, land, flat, traj, t, *span)
        steps_out.append(st)
        if not st.ok:
            reasons.append(
                f"step {k + 1} ({leg} foot, y = {start:.2f} -> {land:.2f} m, {st.method}): "
                + "; ".join(st.reasons)
            )
    if stopped is not None and stopped + 1 < n_planned:
        reasons.append(
            f"steps {stopped + 2}-{n_planned} not planned: the walk cannot go on from a failed swing"
        )
    return steps_out, reasons
