"""CFFTG: a polynomial Collision-Free Foot Trajectory Generator, the baseline of thesis 3.1-3.4 (its
ref. [11] is not public), in NumPy only, returning the same checked ``Trajectory`` as the RL
generator. Its path, apex and re-planning: docs/generation.md (CFFTG, the polynomial baseline).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from jaxexo.baselines import quintic as q5
from jaxexo.config import Config, load_config, scalar_params
from jaxexo.physics import geometry
from jaxexo.physics.scene import check_clearance, stack_scenes, with_clearance
from jaxexo.swing.continuation import check_state
from jaxexo.swing.generator import SwingGenerator
from jaxexo.swing.options import SwingOptions, check_duration, check_points
from jaxexo.swing.trajectory import (
    DEFAULT_DURATION,
    Measured,
    Trajectory,
    TrajectoryBatch,
    assemble,
    measure_paths,
)

DEFAULT_POINTS = 100
C_MAX = 10.0  # |c| bound for a monotone y(s)
APEX_FRAC_RANGE = (0.5 - C_MAX / 64.0, 0.5 + C_MAX / 64.0)  # apex y as a fraction of the step


# Shapes of the height profile: z = h * phi_k(s), phi_k = g(s) (1 + k (1 - 2s)^2) normalised to a
# peak of 1 (g = s^3 (1-s)^3). k = 0 is the plain bell; k = 3 is the flattest top that keeps a single
# apex at s = 1/2 (d phi / d(x^2) at x = s - 1/2 = 0 is proportional to k - 3).
FLATNESS = (0.0, 1.0, 2.0, 3.0)


@functools.lru_cache(maxsize=16)
def plan_basis(n_points: int):
    """Samples s, the minimum-jerk profile, the apex-moving term g = s^3 (1-s)^3 and z's shapes
    phi_k (len(FLATNESS), N), each with peak 1 at s = 1/2 (computed once per n_points, read-only)."""
    s = np.linspace(0.0, 1.0, n_points)
    mj = s**3 * (10.0 - 15.0 * s + 6.0 * s**2)
    g = s**3 * (1.0 - s) ** 3
    k = np.asarray(FLATNESS)[:, None]
    phi = 64.0 * g * (1.0 + k * (1.0 - 2.0 * s) ** 2)
    for a in (s, mj, g, phi):
        a.flags.writeable = False
    return s, mj, g, phi


@functools.lru_cache(maxsize=16)
def _curvature(n_points: int):
    """Bounds on max |d^2/ds^2| over s in [0, 1] of the minimum-jerk profile, of g and of each phi_k,
    and the chord factor (1 / (n - 1))^2 / 8 of samples at s = i / (n - 1): the plan's deviation from
    the polyline through its samples is at most factor * max|c''|. Each bound is the
    maximum on a grid of G points plus half the grid step times a bound on the third derivative
    (the sum of its monomial coefficients' magnitudes, valid on [0, 1])."""
    P = np.polynomial.Polynomial
    s = P([0.0, 1.0])
    g = s**3 * (1 - s) ** 3
    polys = [s**3 * (10 - 15 * s + 6 * s**2), g] + [
        64.0 * g * (1 + k * (1 - 2 * s) ** 2) for k in FLATNESS
    ]
    grid = np.linspace(0.0, 1.0, 2001)
    bounds = np.array(
        [np.abs(p.deriv(2)(grid)).max() + 0.5 / 2000 * np.abs(p.deriv(3).coef).sum() for p in polys]
    )
    return bounds, (1.0 / (n_points - 1)) ** 2 / 8.0


def plan_deviation(start_y, goal_y, apex_frac, apex_h, n_points: int) -> np.ndarray:
    """Bound (B,) in metres on each plan's distance from the polyline through its N samples."""
    b, f = _curvature(n_points)
    c = 64.0 * (np.clip(apex_frac, *APEX_FRAC_RANGE) - 0.5)
    ypp = np.abs(goal_y - start_y) * (b[0] + np.abs(c) * b[1])
    zpp = np.abs(apex_h) * b[2:].max()
    return f * np.sqrt(ypp * ypp + zpp * zpp)


def profile_max(lo: np.ndarray, hi: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Highest point of the obstacles' profiles over the intervals [lo, hi] (B, N), outlines (B, K, 2).

    The profile is piecewise linear, so its maximum over an interval is at an end of the interval
    or at an outline vertex inside it (jaxexo.physics.geometry.profile_height gives the ends)."""
    ol = outline[:, None]  # (B, 1, K, 2)
    vy, vz = ol[..., 0], ol[..., 1]
    inside = (vy >= lo[..., None]) & (vy <= hi[..., None])
    top = np.max(np.where(inside, vz, 0.0), axis=-1)
    n = lo.shape[-1]
    ends = geometry.profile_height(
        np, np.concatenate([lo, hi], axis=-1), ol
    )  # both ends in one pass
    return np.maximum(top, np.maximum(ends[..., :n], ends[..., n:]))


def plan_paths(
    start_y, goal_y, outline, apex_frac, margin, foot_length: float, n_points: int = DEFAULT_POINTS
):
    """Heel paths (B, N, 2) and apex heights (B,) of the polynomial plan (docs/generation.md, CFFTG).

    ``apex_frac`` (B,): the apex's y as a fraction of the step (clipped to the monotone range);
    ``margin`` (B,): clearance asked of the foot, metres. Of the height shapes FLATNESS, each scene
    gets the one that needs the lowest apex."""
    s, mj, g, phi = plan_basis(n_points)
    frac = np.clip(apex_frac, *APEX_FRAC_RANGE)
    c = 64.0 * (frac - 0.5)
    d = (goal_y - start_y)[:, None]
    y = start_y[:, None] + d * (mj + c[:, None] * g)
    m = margin[:, None]
    need = profile_max(y - m, y + foot_length + m, outline)
    req = np.where(need > 0.0, need + m, 0.0)[:, None, :]  # (B, 1, N)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(
            req > 0.0, req / phi, 0.0
        )  # inf where the foot must already be up at s = 0 or 1
    h_k = ratio.max(axis=-1)  # (B, len(FLATNESS))
    best = np.argmin(h_k, axis=1)
    h = np.maximum(h_k[np.arange(len(best)), best], margin)
    h = np.where(np.isfinite(h), h, 0.0)  # infeasible: flat path, the checks report it
    return np.stack([y, h[:, None] * phi[best]], axis=-1), h


@dataclass(frozen=True)
class Plans:
    """``CFFTG.plan`` of B scenes: the final paths (B, N, 2), the via points (B, 3, 2) (start, apex,
    goal), the plans each scene needed (B,), whether it gave up (B,) and the final paths' checks
    (jaxexo.swing.trajectory.Measured)."""

    paths: np.ndarray
    via: np.ndarray
    plans: np.ndarray
    gave_up: np.ndarray
    checks: Measured


def continuation_paths(
    heel, velocity, acceleration, goal_y, tc, c, margin, outline, foot_length, n_points
):
    """Heel paths (B, N, 2), heights h (B,) and deviation bounds (B,) m of continuation plans
    (jaxexo.baselines.quintic): y = y0 H0 + T_c y' H1 + T_c^2 y'' H2 + goal H3 + c D g and
    z = z0 H0 + T_c z' H1 + T_c^2 z'' H2 + h phi_k, the heel's state (B, 2 each) scaled by T_c
    ``tc`` (B,). h is the least that keeps the foot's shadow ``margin`` above the profile at every
    sample after the start (plan_paths's rule on what the quintic z leaves short), for the flatness
    k needing the lowest h, and never negative. The ends are the state's heel and the goal on the
    floor, exactly."""
    values, _, high = q5.continuation_basis(n_points, FLATNESS)
    wy = q5.y_weights(heel, velocity, acceleration, goal_y, tc, c)
    wz = np.zeros((len(tc), len(values)))
    wz[:, :4] = q5.z_weights(heel, velocity, acceleration, tc)
    y = wy @ values[: q5.BASE]
    zq = wz[:, :4] @ values[:4]
    m = margin[:, None]
    # The shadow's reach beside the foot grows from none at the start to the margin at u = 1/2
    # (q5.ramp): the foot starts where it is, beside the obstacle perhaps closer than the margin
    # (never within env.min_clearance: check_state), and cannot jump away; over the obstacle the
    # margin is kept in full. The exact checks judge the curve.
    mh = m * q5.ramp(n_points)
    need = profile_max(y - mh, y + foot_length + mh, outline)
    req = np.where(need > 0.0, need + m, 0.0)[:, None, 1:]  # the start is the state's own
    short = req - zq[:, None, 1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        # inf where the foot must already be up at the goal (phi_k = 0 there)
        ratio = np.where(short > 0.0, short / values[q5.BASE :, 1:], 0.0)
    h_k = ratio.max(axis=-1)  # (B, len(FLATNESS))
    best = np.argmin(h_k, axis=1)
    h = h_k[np.arange(len(best)), best]
    h = np.where(np.isfinite(h), h, 0.0)  # infeasible: the checks report it
    wz[np.arange(len(best)), q5.BASE + best] = h
    paths = np.stack([y, wz @ values], axis=-1)
    paths[:, 0] = heel
    paths[:, -1, 0], paths[:, -1, 1] = goal_y, 0.0
    return paths, h, q5.curve_deviation(wy, wz, high, n_points)


@dataclass(frozen=True)
class ContinuationPlans:
    """``CFFTG.plan_continuation`` of B states: the final paths (B, N, 2), the continuation's duration
    T_c (B,) s that scales the heel's derivatives (the path's dp/du = T_c dp/dt at u = 0), the apex
    term's c (B,), the height h (B,) m, the plans each state needed (B,), whether it gave up (B,)
    and the final paths' checks."""

    paths: np.ndarray
    tc: np.ndarray
    apex_c: np.ndarray
    height: np.ndarray
    plans: np.ndarray
    gave_up: np.ndarray
    checks: Measured


class CFFTG(SwingGenerator):
    """The polynomial generator. ``config`` supplies the kinematics (thigh, shin, foot, joint limits),
    the goal tolerance and the safety distance; pass the RL policy's config to compare like with like.
    ``clearance`` (m; None: env.min_clearance): the margin its swings keep; the verdict judges
    against it, and the plan's margin keeps the same excess above it as the config's
    (reward.safety_distance over env.min_clearance). ``defaults``: generate's options where a call
    gives none. ``sp``: the config's scalar view, when already derived (``with_options``)."""

    name = "cfftg"
    where = "CFFTG."
    not_taken = {
        "smoothing": "CFFTG's polynomial path is not smoothed",
        "fallback": "CFFTG plans every swing itself",
    }

    def __init__(
        self,
        config: Config | None = None,
        *,
        margin: float | None = None,
        margin_step: float = 0.01,
        apex_step: float = 0.02,
        max_plans: int = 10,
        clearance: float | None = None,
        defaults: SwingOptions | None = None,
        sp=None,
    ):
        if isinstance(config, (str, os.PathLike)):
            config = load_config(config)  # a config file's path: the obvious intent
        elif config is None:
            config = Config()  # the default model's settings (configs/default.toml)
        elif not isinstance(config, Config):
            raise TypeError(
                f"config: expected a jaxexo Config or a config file's path, got {type(config).__name__}"
            )
        self.config = config
        self._base_sp = scalar_params(config) if sp is None else sp
        self.clearance = check_clearance(clearance, config.env.min_clearance)
        self.sp = with_clearance(self._base_sp, self.clearance)
        self.margin = geometry.finite(
            "margin", config.reward.safety_distance if margin is None else margin
        )
        if self.margin < 0:
            raise ValueError(f"margin must be >= 0 metres, got {self.margin}")
        if self.clearance is not None:
            self.margin = self.margin + (self.clearance - config.env.min_clearance)
        self.margin_step = geometry.finite_positive("margin_step", margin_step)
        self.apex_step = geometry.finite_positive("apex_step", apex_step)
        if (
            isinstance(max_plans, bool)
            or not isinstance(max_plans, (int, np.integer))
            or max_plans < 1
        ):
            raise ValueError(f"max_plans must be an integer >= 1, got {max_plans!r}")
        self.max_plans = int(max_plans)
        self.defaults = SwingOptions() if defaults is None else defaults

    def with_options(self, **changes) -> "CFFTG":
        """A new CFFTG, this one's construction with ``changes`` (the constructor's keywords), for
        its config as read (not read again from a path) and its scalar view."""
        return CFFTG(self.config, **{**self._made[1], "sp": self._base_sp, **changes})

    # Planning ---------------------------------------------------------------------------------------
    def plan(self, scenes, n_points: int = DEFAULT_POINTS) -> Plans:
        """Plan, check and re-plan every scene (B of them)."""
        arr = stack_scenes(scenes, np.float64)
        b = len(scenes)
        foot = float(self.sp.foot_length)
        # Initial apex: over the middle of the heel positions at which the foot overlaps the obstacle.
        left = arr.center_y - 0.5 * arr.width
        right = arr.center_y + 0.5 * arr.width
        step = arr.goal_y - arr.start_y
        frac0 = (0.5 * (left - foot + right) - arr.start_y) / step
        toward_pivot = np.where(arr.pivot_y > arr.start_y + frac0 * step, 1.0, -1.0)
        margin, frac = np.full(b, self.margin), frac0.copy()
        paths, apex_h, dev = np.zeros((b, n_points, 2)), np.zeros(b), np.zeros(b)

        def plan_group(g, outline):
            paths[g], apex_h[g] = plan_paths(
                arr.start_y[g], arr.goal_y[g], outline, frac[g], margin[g], foot, n_points
            )
            dev[g] = plan_deviation(arr.start_y[g], arr.goal_y[g], frac[g], apex_h[g], n_points)

        def move_apex(mv, alternate, n):
            sign = alternate * toward_pivot[mv]
            frac[mv] = frac0[mv] + sign * n * self.apex_step / step[mv]

        plans, gave_up, checks = self._rounds(scenes, paths, dev, margin, plan_group, move_apex)
        frac_used = np.clip(frac, *APEX_FRAC_RANGE)
        apex = np.stack([arr.start_y + frac_used * step, apex_h], axis=-1)
        via = np.stack(
            [
                np.stack([arr.start_y, np.zeros(b)], -1),
                apex,
                np.stack([arr.goal_y, np.zeros(b)], -1),
            ],
            1,
        )
        return Plans(paths=paths, via=via, plans=plans, gave_up=gave_up, checks=checks)

    def plan_continuation(
        self, scenes, states, n_points: int = DEFAULT_POINTS
    ) -> ContinuationPlans:
        """Plan, check and re-plan the continuation of every foot state (B; jaxexo.swing.replan
        FootState, checked by the caller) over its scene, as ``plan`` re-plans: a plan that touches
        the obstacle again with the margin raised by margin_step, one past a joint limit or the
        leg's length with the apex moved by apex_step, alternately towards and away from the pivot
        (within the range where y stays monotone). T_c: quintic.estimate_tc, halved until y is
        monotone (quintic.monotone_tc); docs/replanning.md (Continuation paths)."""
        arr = stack_scenes(scenes, np.float64)
        heel, vel, acc = (
            np.stack([np.asarray(getattr(st, k), np.float64) for st in states])
            for k in ("heel", "heel_velocity", "heel_acceleration")
        )
        b, foot, goal = len(scenes), float(self.sp.foot_length), arr.goal_y
        margin = np.full(b, self.margin)
        tc0 = q5.estimate_tc(heel, vel, goal, arr.height + margin)
        tc = q5.monotone_tc(heel, vel, acc, goal, tc0)
        lo, hi = q5.apex_range(heel, vel, acc, goal, tc)
        dist = np.maximum(goal - heel[:, 0], 1e-9)
        # The apex starts over the middle of the heel positions at which the foot overlaps the
        # obstacle (``plan``'s rule): c moves y at u = 1/2, where the height shapes peak, there.
        target = arr.center_y - 0.5 * foot
        y_half = q5.y_weights(heel, vel, acc, goal, tc, np.zeros(b))[:, :4] @ q5.HALF
        c0 = 64.0 * (target - y_half) / dist
        toward_pivot = np.where(arr.pivot_y > target, 1.0, -1.0)
        c, paths = np.clip(c0, lo, hi), np.zeros((b, n_points, 2))
        height, dev = np.zeros(b), np.zeros(b)

        def plan_group(g, outline):
            paths[g], height[g], dev[g] = continuation_paths(
                heel[g], vel[g], acc[g], goal[g], tc[g], c[g], margin[g], outline, foot, n_points
            )

        def move_apex(mv, alternate, n):
            sign = alternate * toward_pivot[mv]
            c[mv] = np.clip(c0[mv] + sign * 64.0 * n * self.apex_step / dist[mv], lo[mv], hi[mv])

        plans, gave_up, checks = self._rounds(scenes, paths, dev, margin, plan_group, move_apex)
        return ContinuationPlans(paths, tc, c, height, plans, gave_up, checks)

    def _rounds(self, scenes, paths, dev, margin, plan_group, move_apex):
        """The rounds of ``plan`` and ``plan_continuation``, at most max_plans: ``plan_group(g,
        outlines)`` plans the scenes g still to do into ``paths`` (B, N, 2) and ``dev`` (B,) (the
        scenes grouped by outline size, so that a 16-vertex half-ellipse does not pad rectangles),
        each is checked; one past a joint limit or the leg's length moves its apex (``move_apex(mv,
        alternate, n)``: n apex steps, alternately towards and away from the pivot), one that
        touches the obstacle (kinematics fine) has ``margin`` (B,) raised by margin_step. The plans
        each scene took (B,), whether it gave up (B,) and the final paths' checks."""
        b = len(scenes)
        plans, moves, todo, checks = (
            np.zeros(b, np.int64),
            np.zeros(b, np.int64),
            np.arange(b),
            None,
        )
        sizes = np.array([len(sc.outline) for sc in scenes])
        for _ in range(self.max_plans):
            for k in np.unique(sizes[todo]):
                g = todo[sizes[todo] == k]
                plan_group(g, np.stack([scenes[i].outline for i in g]))
            plans[todo] += 1
            m = measure_paths(self.sp, paths[todo], [scenes[i] for i in todo], dev[todo])
            checks = m if checks is None else _scatter(checks, m, todo)
            # m.ok: the one strict-success verdict (jaxexo.physics.outcome)
            fail, bad_kin = todo[~m.ok], ~(m.joint_limits_ok & m.leg_length_ok)[~m.ok]
            mv = fail[bad_kin]
            moves[mv] += 1
            k = moves[mv]
            move_apex(mv, np.where(k % 2 == 1, 1.0, -1.0), (k + 1) // 2)
            margin[fail[~bad_kin]] += self.margin_step
            todo = fail
            if todo.size == 0:
                break
        gave_up = np.zeros(b, bool)
        gave_up[todo] = True
        return plans, gave_up, checks

    # Trajectories -----------------------------------------------------------------------------------
    def finish(self, scenes, n_points: int, duration: float) -> TrajectoryBatch:
        """Checked trajectories of validated scenes: planned, checked and re-planned (``plan``), with a
        note per scene of the plans it took and where the apex is."""
        p = self.plan(scenes, n_points)
        notes = []
        for i in range(len(scenes)):
            y, z = p.via[i, 1]
            note = f"cfftg: {p.plans[i]} plan(s); apex y={y:.3f} m, z={z:.3f} m"
            notes.append(
                (note + f"; gave up after {self.max_plans} plans",) if p.gave_up[i] else (note,)
            )
        return assemble(
            self.name,
            self.sp,
            scenes,
            list(p.via),
            p.paths,
            np.zeros(len(scenes)),
            duration,
            notes,
            measured=p.checks,
        )

    def continuation_batch(
        self,
        scenes,
        states,
        *,
        n_points: int = DEFAULT_POINTS,
        duration: float = DEFAULT_DURATION,
        swing_scenes=None,
    ) -> TrajectoryBatch:
        """``continuation`` of many foot states, one per scene (and, when given, one swing scene
        each), planned together (``plan_continuation``), with a note per state of the plans it
        took, T_c, the height and the apex term."""
        n_points, duration = check_points(n_points), check_duration(duration)
        scenes, states = list(scenes), list(states)
        olds = [None] * len(scenes) if swing_scenes is None else list(swing_scenes)
        if not (len(scenes) == len(states) == len(olds)) or not scenes:
            raise ValueError(
                f"scenes, states, swing_scenes: one state (and swing scene) per scene, got "
                f"{len(scenes)} scenes, {len(states)} states and {len(olds)} swing scenes"
            )
        for sc, st, old in zip(scenes, states, olds):
            check_state(st, sc, self.sp, old)
        p = self.plan_continuation(scenes, states, n_points)
        notes, vias = [], []
        for i in range(len(scenes)):
            note = (
                f"cfftg continuation: {p.plans[i]} plan(s); T_c={p.tc[i]:.3f} s, "
                f"height term {p.height[i]:.3f} m, apex term c={p.apex_c[i]:.2f}"
            )
            gave_up = (f"; gave up after {self.max_plans} plans",) if p.gave_up[i] else ()
            notes.append((note + "".join(gave_up),))
            vias.append(p.paths[i, [0, n_points // 2, -1]])  # start, u = 1/2 (the apex), goal
        return assemble(
            self.name,
            self.sp,
            scenes,
            vias,
            p.paths,
            np.zeros(len(scenes)),
            duration,
            notes,
            measured=p.checks,
        )

    def continuation(
        self,
        scene,
        state,
        *,
        n_points: int = DEFAULT_POINTS,
        duration: float = DEFAULT_DURATION,
        swing_scene=None,
    ) -> Trajectory:
        """CFFTG's heel path from the foot's state (jaxexo.swing.replan.FootState: mid-air, moving)
        over ``scene`` (the new obstacle, laid out with the swing's pivot, start and goal: with
        ``swing_scene``, the swing's own scene, that is checked) to the goal, landing at rest:
        quintic y and z matching the heel's position, velocity and acceleration at its start (scaled
        by T_c) plus CFFTG's height term, checked and re-planned (``plan_continuation``;
        docs/replanning.md, Continuation paths). Its heel[0] is the state's heel exactly.
        ValueError (jaxexo.swing.continuation.check_state) for a foot already within the margin of
        the new obstacle, a scene with other feet, bad n_points or duration."""
        return self.continuation_batch(
            [scene], [state], n_points=n_points, duration=duration, swing_scenes=[swing_scene]
        )[0]

    def describe(self, traj) -> str:
        return "polynomial path (CFFTG)"

    def plan_batch(self, scenes, o: SwingOptions) -> TrajectoryBatch:
        """``finish`` with the options' n_points and duration (the generator interface's step)."""
        return self.finish(scenes, o.n_points, o.duration)

    def continue_from(self, scene, state, o, swing_scene) -> Trajectory:
        """``continuation`` with the options' n_points and duration (``replan``'s step)."""
        return self.continuation(
            scene, state, n_points=o.n_points, duration=o.duration, swing_scene=swing_scene
        )


def _scatter(full: Measured, part: Measured, idx: np.ndarray) -> Measured:
    """Write the checks of re-planned scenes ``idx`` into the batch's checks (in place)."""
    for k, v in vars(part).items():
        getattr(full, k)[idx] = v
    return full
