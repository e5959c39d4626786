"""``plan_course``: a walk over a course planned swing by swing with a generator and timed for the
device (jaxexo.course, 2. and 3.)."""

from __future__ import annotations

import dataclasses
import time as _time
from dataclasses import dataclass
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
from jaxexo.course.record import (
    JUNCTION_TOL,
    LEGS,
    WALK_COLUMNS,
    Course,
    CourseStep,
    SwingPlace,
    TerrainUpdate,
    walk_table,
)
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
    updates=None,
) -> Course:
    """Plan a walk over ``terrain`` (a Terrain, a terrain file's path or (y, z) points) with
    ``generator`` (a swing generator: TrajectoryGenerator, CFFTG, ...): the footholds
    (``footholds``), each swing (``fallback``: "cfftg" or None, for a generator that takes it),
    timed at the device ``limits`` (default: the config's [device]) and sampled at ``rate`` Hz
    (default: its control rate), with a ``double_support`` dwell (s) at each landing. Infeasible
    courses and bad options raise CourseError (TerrainFileError for bad points) before any swing is
    planned; a walk whose swings fail is returned with ``ok`` False and the reasons. ``updates``: a
    TerrainUpdate or a list of them: from each one's time on the walk goes on over its terrain, the
    swing in flight replanned (``_apply_update``)."""
    from jaxexo.swing.generator import SwingGenerator
    from jaxexo.swing.options import check_fallback
    from jaxexo.swing.timing import DeviceLimits, time_swings

    t0 = _time.perf_counter()
    if not isinstance(generator, SwingGenerator):
        raise CourseError(
            f"generator: expected a swing generator (a TrajectoryGenerator, CFFTG, ...), got "
            f"{type(generator).__name__}"
        )
    config = generator.config
    fallback = check_fallback(fallback)
    terrain = _as_terrain(terrain)
    ds = check_double_support("double_support", double_support)
    limits = DeviceLimits.from_config(config) if limits is None else limits
    gen = generator.at_clearance(clearance)
    if gen.takes("fallback"):
        gen = gen.with_defaults(fallback=fallback)
    r = FootholdRules.of(config, clearance)
    _check_size(terrain, config, r, limits, rate, start_y, goal_y, steps, ds)
    updates = _checked_updates(updates)
    plan = footholds(
        terrain, config, start_y=start_y, goal_y=goal_y, steps=steps, clearance=clearance
    )
    trajs, meta, stopped = _swings(gen, plan, terrain, r)
    # A failed swing is not timed (its path may not be one a drive can follow).
    good = [t for t in trajs if t.ok]
    timed = time_swings(good, config, rate=rate, limits=limits, sp=gen.sp) if good else []
    rate = timed[0].rate if timed else float(config.device.control_rate if rate is None else rate)
    walk = _Walk(trajs, meta, timed, stopped, [None] * len(trajs))
    ctx = _Context(gen, plan, r, ds, rate, limits)
    for i, u in updates:
        walk = _apply_update(ctx, walk, u, i)
    trajs, meta, timed, stopped = walk.trajs, walk.meta, walk.timed, walk.stopped
    samples, spans, jump = walk_table(timed, meta, ds, rate)
    steps_out, reasons = _steps(trajs, meta, timed, spans, stopped, len(plan), walk.before)
    if jump > JUNCTION_TOL:
        reasons.append(
            f"the joint angles jump by {jump:.2e} rad where one swing hands over to the next"
        )
    notes = tuple(
        f"step {s.index + 1}: {s.method}" for s in steps_out if s.method != generator.name
    )
    return Course(
        terrain=terrain,
        footholds=plan,
        steps=tuple(steps_out),
        rate=float(rate),
        limits=limits,
        double_support=ds,
        method=generator.name,
        samples=samples,
        junction_jump=jump,
        reasons=tuple(reasons),
        plan_seconds=_time.perf_counter() - t0,
        notes=notes + walk.notes,
        updates=tuple(u for _, u in updates),
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


def _swings(gen, plan, terrain: Terrain, r: FootholdRules, first=0, feet=None):
    """Each swing of the walk in order from ``first`` (the feet's heel y then: ``feet``, left and
    right; default both at the start), until one fails: (trajectories, each swing's SwingPlace,
    the index of the failed swing or None)."""
    feet = [plan.start_y, plan.start_y] if feet is None else list(feet)
    obs = obstacles_of(terrain)
    trajs, meta, stopped = [], [], None
    for k in range(first, len(plan)):
        leg = k % 2
        start, pivot, goal = feet[leg], feet[1 - leg], plan.landings[k]
        ob, flat = _swing_obstacle(obs, start, goal, r, terrain)
        # The policy observes absolute positions (it is trained with starts 0-12 cm): each swing is
        # planned in its own frame, starting at y = 0, and placed on the course after.
        kw = dict(pivot_y=pivot - start, start_y=0.0, step_length=goal - start)
        local = _shifted(ob, -start)
        traj = gen.generate(local, **kw)
        traj = _in_course(traj, gen, ob, start, pivot, goal)
        feet[leg] = float(traj.heel[-1, 0])
        trajs.append(traj)
        place = dict(index=k, leg=LEGS[leg], start_y=start, pivot_y=pivot, goal_y=goal)
        meta.append(SwingPlace(**place, landing_y=feet[leg], flat=flat))
        if not traj.ok:
            stopped = k
            break
    return trajs, meta, stopped


def _steps(trajs, meta, timed, spans, stopped, n_planned: int, before):
    """The walk's steps (CourseStep, the swings not timed with no time of their own; ``before``:
    each one's swing before a replan, or None) and the reasons of those that failed, and of the
    steps not planned after a failed swing."""
    end = spans[-1][1] if spans else 0.0
    timed = timed + [None] * (len(trajs) - len(timed))
    spans = spans + [(end, end)] * (len(trajs) - len(spans))
    steps_out, reasons = [], []
    for m, traj, t, span, old in zip(meta, trajs, timed, spans, before):
        st = CourseStep(
            **vars(m), trajectory=traj, timed=t, start_s=span[0], end_s=span[1], replanned_from=old
        )
        steps_out.append(st)
        if not st.ok:
            reasons.append(
                f"step {m.index + 1} ({m.leg} foot, y = {m.start_y:.2f} -> {m.landing_y:.2f} m, "
                f"{st.method}): " + "; ".join(st.reasons)
            )
    if stopped is not None and stopped + 1 < n_planned:
        reasons.append(
            f"steps {stopped + 2}-{n_planned} not planned: the walk cannot go on from a failed swing"
        )
    return steps_out, reasons


# --------------------------------------------------------------------------------------------
# Terrain updates: the swing in flight replanned, the swings after planned on the new terrain
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Context:
    """What a walk's swings are planned and timed with (``plan_course``'s, checked)."""

    gen: object  # the generator at the walk's clearance, with its fallback option
    plan: object  # Footholds
    rules: FootholdRules
    double_support: float
    rate: float
    limits: object


@dataclass(frozen=True)
class _Walk:
    """A walk being planned: the swings' trajectories, their SwingPlaces, the timed swings (the first len(timed)), the failed swing's index or None,
    each swing's TimedSwing before a replan (or None), and notes."""

    trajs: list
    meta: list
    timed: list
    stopped: int | None
    before: list
    notes: tuple = ()


def _checked_updates(updates) -> tuple:
    """``updates`` (None, a TerrainUpdate or a list of them) as (i, TerrainUpdate) with the
    terrain read, at distinct times >= 0, in time order (i: its place in the list given, which
    messages name); CourseError naming ``updates[i]`` otherwise."""
    if updates is None:
        return ()
    if isinstance(updates, TerrainUpdate):
        updates = [updates]
    if not isinstance(updates, (list, tuple)):
        raise CourseError(
            f"updates: expected a TerrainUpdate or a list of them, got {type(updates).__name__}"
        )
    out = []
    for i, u in enumerate(updates):
        if not isinstance(u, TerrainUpdate):
            raise CourseError(f"updates[{i}]: expected a TerrainUpdate, got {type(u).__name__}")
        t = check_number(f"updates[{i}].time", u.time, 0.0)
        out.append((t, i, TerrainUpdate(t, _as_terrain(u.terrain))))
    out.sort(key=lambda x: x[0])
    for (t, i, _), (t2, j, _) in zip(out, out[1:]):
        if t == t2:
            raise CourseError(
                f"updates[{j}]: at t = {geometry.as_given(t)} s, the time of updates[{i}] too; "
                "give one terrain per instant"
            )
    return tuple((i, u) for _, i, u in out)


def _apply_update(ctx: _Context, walk: _Walk, u: TerrainUpdate, i: int) -> _Walk:
    """The walk with update ``u`` (``updates[i]``) applied: the swing in flight at u.time (lifted
    off before it, landing after it) replanned at that instant over u.terrain's obstacle for it
    (``_swing_obstacle``'s rule), the swings not yet started planned on u.terrain with the same
    footholds. Refused (CourseError) where a place a foot stands on from then on is not flat ground
    on the new terrain, or after the walk's end; not applied after a failed swing (a note)."""
    spans = walk_table(walk.timed, walk.meta, ctx.double_support, ctx.rate)[1]
    name = f"updates[{i}] (t = {geometry.as_given(u.time)} s)"
    k = next(
        (j for j, (a, t) in enumerate(zip(spans, walk.timed)) if a[0] + t.duration > u.time), None
    )
    if k is None or (walk.stopped is not None and k >= walk.stopped):
        if walk.stopped is not None:
            note = f"{name} not applied: the walk stopped at the failed step {walk.stopped + 1}"
            return dataclasses.replace(walk, notes=walk.notes + (note,))
        end = spans[-1][0] + walk.timed[-1].duration if spans else 0.0
        raise CourseError(
            f"{name}: the walk has landed by then (its last swing lands at {end:.3f} s)"
        )
    _check_footholds(ctx, walk.meta, k, u.terrain, name)
    trajs, meta, timed = walk.trajs[:k], walk.meta[:k], walk.timed[:k]
    before = walk.before[:k]
    first, feet = k, _feet(ctx.plan, meta)
    if spans[k][0] < u.time:  # in flight: replanned
        new, flat = _replanned(ctx, walk.timed[k], walk.meta[k], u, u.time - spans[k][0], name)
        place = dataclasses.replace(walk.meta[k], landing_y=float(new.heel[-1, 0]), flat=flat)
        trajs, meta, timed = (
            trajs + [walk.trajs[k]],
            meta + [place],
            timed + [new],
        )
        before = before + [walk.timed[k] if walk.before[k] is None else walk.before[k]]
        if not new.ok:  # the walk stops there, as at any failed swing (timed: it is under way)
            return _Walk(trajs, meta, timed, k, before, walk.notes)
        first, feet = k + 1, _feet(ctx.plan, meta)
    more, more_meta, stopped = _swings(ctx.gen, ctx.plan, u.terrain, ctx.rules, first, feet)
    from jaxexo.swing.timing import time_swings

    good = [t for t in more if t.ok]
    g = ctx.gen
    more_timed = (
        time_swings(good, g.config, rate=ctx.rate, limits=ctx.limits, sp=g.sp) if good else []
    )
    return _Walk(
        trajs + more,
        meta + more_meta,
        timed + more_timed,
        stopped,
        before + [None] * len(more),
        walk.notes,
    )


def _feet(plan, meta) -> list[float]:
    """The heel y of the left and right foot after the swings of ``meta``."""
    feet = [plan.start_y, plan.start_y]
    for m in meta:
        feet[LEGS.index(m.leg)] = m.landing_y
    return feet


def _check_footholds(ctx: _Context, meta, k: int, terrain: Terrain, name: str) -> None:
    """Every place a foot stands on from swing k on (its start and pivot, as the feet stand, and
    each landing still to come, within the landing tolerance) on flat ground of ``terrain`` by the
    footholds' rule (the foot and FootholdRules.stand either side clear of every obstacle), and on
    the course: the footholds are not moved by an update; CourseError otherwise."""
    r = ctx.rules
    obs = obstacles_of(terrain)
    places = [(meta[k].start_y, 0.0, "stands"), (meta[k].pivot_y, 0.0, "stands")]
    places += [(y, r.tolerance, "lands") for y in ctx.plan.landings[k:]]
    y0, y1 = float(terrain.y[0]), float(terrain.y[-1])
    for y, tol, does in places:
        lo, hi = y - tol - r.stand, y + r.foot + tol + r.stand
        if lo + r.stand < y0 or hi - r.stand > y1:
            raise CourseError(
                f"{name}: a foot {does} at y = {y:.3f} m, off its terrain ({terrain.source}: y = "
                f"{y0:.3f} to {y1:.3f} m); an update keeps the footholds"
            )
        for ob in obs:
            if ob[0, 0] < hi and ob[-1, 0] > lo:
                raise CourseError(
                    f"{name}: a foot {does} at y = {y:.3f} m, on or within {r.stand * 100:.1f} cm "
                    f"of {describe(ob)} of {terrain.source}; an update keeps the footholds (plan "
                    "the walk again from where the feet are)"
                )


def _moved(swing, gen, dy: float):
    """The TimedSwing ``swing`` moved by ``dy`` along the course: its scene (obstacle, pivot, start,
    goal), the curve's pivot and every sampled position; the joints, times and verdict as they are
    (the legs' motion does not depend on where along the floor it happens)."""
    sc = swing.scene
    scene = gen.scene(
        _shifted(sc.obstacle, dy),
        pivot_y=sc.pivot_y + dy,
        start_y=sc.start_y + dy,
        step_length=sc.goal_y - sc.start_y,
    )
    scene = scene._replace(goal_y=sc.goal_y + dy, pivot_kind=sc.pivot_kind)
    shift = np.array([dy, 0.0])
    return dataclasses.replace(
        swing,
        scene=scene,
        curve=dataclasses.replace(swing.curve, pivot_y=swing.curve.pivot_y + dy),
        **{
            f: getattr(swing, f) + shift
            for f in ("heel", "toe", "hip", "knee_swing", "knee_stance")
        },
    )


def _replanned(ctx: _Context, swing, m, u: TerrainUpdate, at: float, name: str):
    """Swing ``m`` (its SwingPlace) replanned at ``at`` (s, swing time) over u.terrain's obstacle for it:
    in its own frame, as it was planned (the policy observes positions from its start), by the
    generator's ``replan``; (the replanned TimedSwing on the course, whether it is flat)."""
    k, start = m.index, m.start_y
    ob, flat = _swing_obstacle(obstacles_of(u.terrain), start, m.goal_y, ctx.rules, u.terrain)
    local = _moved(swing, ctx.gen, -start)
    try:
        new = ctx.gen.replan(local, _shifted(ob, -start), at=at)
    except ValueError as e:
        raise CourseError(
            f"{name}: step {k + 1}'s swing in flight cannot be replanned: {e}"
        ) from None
    return _moved(new, ctx.gen, start), flat
