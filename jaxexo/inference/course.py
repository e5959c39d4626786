"""A walk over a course: a measured ground profile in, footholds and both legs' joint trajectories out,
timed for the device (NumPy only).

The course (jaxexo.storage.terrain_file.Terrain) is the ground's height along the walk; every
stretch where it rises above the floor is an obstacle. The walk starts with both feet together at
``start_y`` and ends with both feet together at the goal. Swings alternate legs, the left first:
swing k moves one foot from its last foothold over the terrain between to the next, with the other
foot standing as its pivot (``pivot_y``), as the thesis's single swing does.

1. Footholds (``footholds``), before any swing is planned. A foothold is a point of a 1 cm grid
   where the foot (heel and toe) stands on flat ground (z = 0) with ``STAND_MARGIN`` or the asked
   clearance + 5 mm to spare from any obstacle, widened by the goal tolerance (env.goal_tolerance:
   the swing may end that far from its goal, and the foot must stand clear wherever it lands).
   A swing from a to c with pivot b is allowed when its length c - a lies in the config's step
   range (the terrain layout's when it trains on terrain), a <= b <= c, every obstacle under it fits
   in the policy's profile (geometry.MAX_PROFILE_VERTICES) and the heel held the mid-goal box's
   bottom above each of its vertices is within reach and joint limits for every pivot within the
   goal tolerance of b (kinematics.swing_heel_unreachable, the rule jaxexo.config checks a config's
   obstacles by). Among the walks allowed, a shortest path on the states (trailing foot, leading
   foot) picks the one of least cost: one per swing plus the squared deviations, in half step
   ranges, of each swing's length from the nominal (the middle of the range) and of its pivot from
   the middle of the swing (a steady gait; the first and last swings start and end with the feet
   together). A course no walk crosses is refused (``CourseError``) with the position of what
   stops it: an obstacle no swing clears, one wider than the longest step, a gap with no flat
   foothold in reach.
2. Swings, in order (each starts where the last swing of its leg landed): the generator's swing
   (``generate`` with ``pivot_y``) over the obstacles between its start and goal as one
   ``Obstacle.profile``; on flat ground, over a low virtual obstacle (``FLAT_OBSTACLE``) so the
   foot lifts off. The RL generator falls back on CFFTG per step unless ``fallback=None``; the
   step's method says which planned it. Every safe swing ends with the foot on the floor: CFFTG's by
   construction, the RL swing's because its descent to the floor is part of the smoothed and checked
   path (jaxexo.inference.finish.landed). A swing that fails (short of the goal, maybe above the
   floor) stops the walk, as it fails a single swing.
3. Timing (swing_timing.time_swings): every swing rest-to-rest at the [device] limits, sampled at
   the control rate. At a landing both legs are straight with the hip between the heels (the hip
   model of jaxexo.physics.kinematics), so the landing pose of one swing is the lift-off pose of
   the next with the legs' roles swapped, and both are at rest: q, q-dot and q-double-dot are
   continuous (checked at every junction: ``Course.junction_jump``). A double-support dwell of
   ``double_support`` s can be held at each landing (default 0: none is needed).

Units: metres, radians, seconds.
"""

from __future__ import annotations

import dataclasses
import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxexo.inference.export import timed_dict, write_csv, write_json
from jaxexo.inference.trajectory import Trajectory, assemble
from jaxexo.physics import geometry, kinematics
from jaxexo.physics.terrain import NEAR_MARGIN
from jaxexo.storage.terrain_file import Terrain, read_terrain

GRID = 0.01  # m, foothold resolution
STAND_MARGIN = (
    NEAR_MARGIN  # m, least distance of a standing foot from an obstacle (the training's toe margin)
)
FLAT_OBSTACLE = (
    0.10,
    0.03,
)  # m, (width, height) of the virtual obstacle a swing on flat ground lifts over
JUNCTION_TOL = 1e-6  # rad, largest joint-angle jump allowed where one swing hands over to the next
MAX_STEPS = 1000  # swings in one walk (``steps``)
MAX_DOUBLE_SUPPORT = 10.0  # s

LEGS = ("left", "right")
WALK_JOINTS = ("hip_left", "knee_left", "hip_right", "knee_right")
WALK_COLUMNS = (
    (
        "time_s",
        "step",
        "swing_leg",
        "left_heel_y_m",
        "left_heel_z_m",
        "left_toe_y_m",
        "left_toe_z_m",
        "right_heel_y_m",
        "right_heel_z_m",
        "right_toe_y_m",
        "right_toe_z_m",
        "hip_y_m",
        "hip_z_m",
        "left_knee_y_m",
        "left_knee_z_m",
        "right_knee_y_m",
        "right_knee_z_m",
    )
    + tuple(f"{j}_rad" for j in WALK_JOINTS)
    + tuple(f"{j}_vel_rad_s" for j in WALK_JOINTS)
    + tuple(f"{j}_acc_rad_s2" for j in WALK_JOINTS)
)


class CourseError(ValueError):
    """A course that cannot be walked (or a bad option); the message names the position along it."""


# --------------------------------------------------------------------------------------------
# The terrain's obstacles
# --------------------------------------------------------------------------------------------


def obstacles_of(terrain: Terrain) -> list[np.ndarray]:
    """The terrain's obstacles, in order: each a (n, 2) run of profile points above the floor, with
    the floor point on either side where the profile has one."""
    z = terrain.z
    up = z > 0.0
    if not up.any():
        return []
    prev = np.concatenate([[False], up[:-1]])
    nxt = np.concatenate([up[1:], [False]])
    starts = np.flatnonzero(up & ~prev)
    ends = np.flatnonzero(up & ~nxt)
    pts = terrain.points
    return [pts[max(i - 1, 0) : min(j + 2, len(z))] for i, j in zip(starts, ends)]


def _describe(ob: np.ndarray) -> str:
    return (
        f"the obstacle at y = {ob[0, 0]:.2f}-{ob[-1, 0]:.2f} m ({ob[:, 1].max() * 100:.0f} cm high)"
    )


# --------------------------------------------------------------------------------------------
# Footholds
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FootholdRules:
    """The numbers footholds are chosen by (metres), from a config and a clearance."""

    foot: float
    stand: float  # flat ground a standing foot keeps on either side
    tolerance: float  # how far a swing may land from its goal (env.goal_tolerance[0])
    lo: float  # swing length range
    hi: float
    lift: float  # heel height above an obstacle's vertices that must be within reach
    thigh: float
    shin: float
    hip_limits: tuple
    knee_limits: tuple

    @classmethod
    def of(cls, config, clearance: float | None = None) -> "FootholdRules":
        env, kin, lay = config.env, config.kinematics, config.layout
        c = env.min_clearance if clearance is None else float(clearance)
        steps = lay.terrain.step_length if lay.terrain is not None else lay.step_length
        return cls(
            foot=float(kin.foot_length),
            stand=max(STAND_MARGIN, c + 0.005),
            tolerance=float(env.goal_tolerance[0]),
            lo=float(steps[0]),
            hi=float(steps[1]),
            lift=max(c, env.mid_goal_clearance - env.mid_goal_half_size[1]),
            thigh=float(kin.thigh),
            shin=float(kin.shin),
            hip_limits=tuple(kin.hip_limits),
            knee_limits=tuple(kin.knee_limits),
        )

    @property
    def nominal(self) -> float:
        return 0.5 * (self.lo + self.hi)


@dataclass(frozen=True)
class Footholds:
    """The planned walk: ``landings[k]`` is where swing k's foot lands (its goal), the left foot on
    even k; ``start_y`` where both feet stand at first. Swing k starts at the landing two before it
    (the start for k < 2) and pivots on the one before it (the start for k = 0)."""

    start_y: float
    landings: tuple[float, ...]

    def swing(self, k: int) -> tuple[float, float, float]:
        """(start, pivot, goal) of swing k, m."""
        y = (self.start_y, self.start_y) + self.landings
        return y[k], y[k + 1], y[k + 2]

    def __len__(self) -> int:
        return len(self.landings)


def _check_number(name: str, v, lo=None, integer=False):
    if v is None:
        return None
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise CourseError(f"{name}: expected a number, got {v!r}")
    if integer and int(v) != v:
        raise CourseError(f"{name}: expected a whole number, got {v!r}")
    v = int(v) if integer else float(v)
    if not math.isfinite(v) or (lo is not None and v < lo):
        raise CourseError(f"{name}: must be a finite number >= {lo}, got {v!r}")
    return v


def footholds(
    terrain: Terrain,
    config,
    *,
    start_y: float | None = None,
    goal_y: float | None = None,
    steps: int | None = None,
    clearance: float | None = None,
) -> Footholds:
    """Choose the footholds of a walk over ``terrain`` (module docstring, 1.): from ``start_y``
    (default: the terrain's first point) to ``goal_y`` (default: the furthest foothold the terrain
    allows), or, with ``steps``, the walk of exactly that many swings. CourseError naming the
    position when no walk exists."""
    if steps is not None and goal_y is not None:
        raise CourseError("goal_y, steps: give one of them (where to go, or how many swings)")
    steps = _check_number("steps", steps, 1, integer=True)
    if steps is not None and steps > MAX_STEPS:
        raise CourseError(f"steps: at most {MAX_STEPS} swings, got {steps}")
    r = FootholdRules.of(config, clearance)
    obs = obstacles_of(terrain)
    y0, y_end = float(terrain.y[0]), float(terrain.y[-1])
    start = y0 if start_y is None else _check_number("start_y", start_y)
    if not y0 <= start <= y_end - r.foot:
        raise CourseError(
            f"start_y: {start:.3f} m is not on the course (the foot must stand between "
            f"{y0:.3f} and {y_end - r.foot:.3f} m)"
        )
    lefts = np.array([o[0, 0] for o in obs])
    rights = np.array([o[-1, 0] for o in obs])
    blocked = _overlapping(
        lefts, rights, np.array([start - r.stand]), np.array([start + r.foot + r.stand])
    )[0]
    if blocked >= 0:
        raise CourseError(
            f"start_y: the feet at y = {start:.3f} m do not stand on flat ground {r.stand * 100:.1f} cm "
            f"clear of {_describe(obs[blocked])}"
        )
    n = int(math.floor((y_end - r.foot - r.tolerance - start) / GRID + 1e-9)) + 1
    if n < 2:
        raise CourseError(
            f"terrain: the course ends at y = {y_end:.3f} m, too close to the start for a step"
        )
    ys = start + GRID * np.arange(n)
    over = _overlapping(
        lefts, rights, ys - r.tolerance - r.stand, ys + r.foot + r.tolerance + r.stand
    )
    valid = over < 0
    valid[0] = True  # the start (checked above, without the landing tolerance)
    if goal_y is not None:
        goal_y = _check_number("goal_y", goal_y)
        g = int(round((goal_y - start) / GRID))
        if g <= 0:
            raise CourseError(f"goal_y: {goal_y:.3f} m must lie ahead of the start ({start:.3f} m)")
        if g >= n:
            raise CourseError(
                f"goal_y: {goal_y:.3f} m is beyond the last place a foot can land on the course "
                f"({ys[-1]:.3f} m: the terrain ends at {y_end:.3f} m)"
            )
        if not valid[g]:
            raise CourseError(
                f"goal_y: a foot at y = {ys[g]:.3f} m does not stand on flat ground clear of "
                f"{_describe(obs[over[g]])}"
            )
    planner = _Planner(r, ys, valid, obs, lefts, rights)
    if steps is not None:
        path = planner.fixed_steps(steps)
        if path is None:
            raise CourseError(planner.why_not(f"no walk of {steps} swings on this course"))
    elif goal_y is not None:
        path = planner.to_goal(g)
        if path is None:
            raise CourseError(planner.why_not(f"no walk reaches the goal y = {ys[g]:.2f} m"))
    else:
        # The default goal: the furthest place both feet can stand together, past every obstacle.
        path = planner.to_goal(None)
        if not path:
            raise CourseError(
                planner.why_not(
                    f"terrain: no walk from y = {start:.2f} m ends with both feet together "
                    f"(steps of {r.lo:.2f}-{r.hi:.2f} m)"
                )
            )
        end = ys[path[-1]]
        left_out = np.flatnonzero(rights > end)
        if left_out.size:
            raise CourseError(
                planner.why_not(f"no walk gets past {_describe(obs[int(left_out[0])])}")
            )
    return Footholds(float(start), tuple(float(ys[k]) for k in path))


def _overlapping(lefts, rights, lo, hi) -> np.ndarray:
    """For each window (lo, hi) (m): the index of an obstacle reaching into it, or -1."""
    if lefts.size == 0:
        return np.full(len(lo), -1)
    i = np.searchsorted(lefts, hi, side="left")  # obstacles starting before the window's end ...
    j = np.searchsorted(rights, lo, side="right")  # ... less those ending at or before its start
    return np.where(i > j, j, -1)


class _Planner:
    """The shortest-path search over states (trailing foot a, leading foot b) on the foothold grid;
    a state is stored at [b, b - a]."""

    def __init__(self, r: FootholdRules, ys, valid, obs, lefts, rights):
        self.r, self.ys, self.valid, self.obs = r, ys, valid, obs
        self.n = len(ys)
        self.lo = int(math.ceil(r.lo / GRID - 1e-9))
        self.hi = int(math.floor(r.hi / GRID + 1e-9))
        self.sigma = 0.5 * (self.hi - self.lo) if self.hi > self.lo else 1.0
        # Swing (a, c) covers obstacle j when a < left_j and right_j < c: grid bounds per obstacle.
        self.a_below = np.ceil((lefts - ys[0]) / GRID - 1e-9).astype(np.int64)  # a index < this
        self.c_above = np.floor((rights - ys[0]) / GRID + 1e-9).astype(np.int64)  # c index > this
        sizes = np.array([len(o) for o in obs], np.int64)
        self.too_many = sizes > geometry.MAX_PROFILE_VERTICES - 2
        self.vert_cum = np.concatenate([[0], np.cumsum(sizes)])
        idx = np.arange(self.n)
        self.first_after = np.searchsorted(
            self.a_below, idx, side="right"
        )  # obstacles with a_below > a
        self.last_before = np.searchsorted(
            self.c_above, idx, side="left"
        )  # obstacles with c_above < c
        self.lefts, self.rights = lefts, rights
        self._clear = {}

    def clears(self, j: int) -> tuple[int, np.ndarray]:
        """(k0, ok): whether obstacle j can be cleared with the pivot at grid k0 + i, for the pivots a
        swing over it can have (within the longest step of it), and every pivot within the
        landing tolerance of it."""
        if j in self._clear:
            return self._clear[j]
        r, ob = self.r, self.obs[j]
        k0 = max(0, int(self.c_above[j]) - self.hi)
        k1 = min(self.n, int(self.a_below[j]) + self.hi + 1)
        tol = int(math.ceil(r.tolerance / GRID - 1e-9))
        piv = self.ys[0] + GRID * np.arange(k0 - tol, k1 + tol)
        top = ob[ob[:, 1] > 0.0]
        heels = np.concatenate([top, top - [r.foot, 0.0]]) + [0.0, r.lift]
        hb = np.broadcast_to(heels, (len(piv),) + heels.shape)
        bad = kinematics.swing_heel_unreachable(
            np, piv[:, None], hb, r.thigh, r.shin, r.hip_limits, r.knee_limits
        ).any(axis=1)
        ok = ~bad
        if tol:
            win = np.lib.stride_tricks.sliding_window_view(ok, 2 * tol + 1)
            ok = win.all(axis=1)
        out = (k0, ok[: k1 - k0])
        self._clear[j] = out
        return out

    def _costs(self, b: int, src: np.ndarray, together: bool, last: int | None):
        """Candidate costs from the states (b - d, b) with costs src (H+1,) to (b, b + e): e = 0 only
        (``together``) or e = 1..H; returns (cost (E,), best d (E,))."""
        H = self.hi
        d = np.arange(H + 1)[:, None]
        e = np.array([0]) if together else np.arange(1, H + 1)
        e = e[None, :]
        a, c = b - d, b + e
        s = d + e
        ok = (a >= 0) & (c < self.n) & (s >= self.lo) & (s <= H) & np.isfinite(src)[:, None]
        cc = np.clip(c, 0, self.n - 1)
        ok &= self.valid[cc]
        if together:
            ok &= d > 0
        if not ok.any():
            return np.full(e.shape[1], np.inf), np.zeros(e.shape[1], np.int64)
        aa = np.clip(a, 0, self.n - 1)
        j0, j1 = self.first_after[aa], self.last_before[cc]
        ok &= (
            self.vert_cum[np.maximum(j1, j0)] - self.vert_cum[j0]
            <= geometry.MAX_PROFILE_VERTICES - 2
        )
        lo_j = int(self.first_after[max(b - H, 0)])
        hi_j = int(self.last_before[min(b + H, self.n - 1)])
        for j in range(lo_j, hi_j):
            k0, clear = self.clears(j)
            i = b - k0
            if 0 <= i < len(clear) and clear[i] and not self.too_many[j]:
                continue
            ok &= ~((a < self.a_below[j]) & (c > self.c_above[j]))
        dev = (s - 0.5 * (self.lo + H)) / self.sigma
        piv = (d - e) / (2.0 * self.sigma)
        first = b == 0
        cost = 1.0 + dev * dev + np.where(first | ((c == last) & (e == 0)), 0.0, piv * piv)
        tot = np.where(ok, src[:, None] + cost, np.inf)
        best = np.argmin(tot, axis=0)
        return tot[best, np.arange(tot.shape[1])], best

    def to_goal(self, g: int | None):
        """Grid indices of the landings of the least-cost walk to both feet at g (None: the furthest
        grid point where both feet can stand together; [] when none), or None."""
        H, n = self.hi, self.n
        furthest = g is None
        g = n - 1 if furthest else g
        cost = np.full((n, H + 1), np.inf)
        pred = np.full((n, H + 1), -1, np.int64)
        cost[0, 0] = 0.0
        self.reach = 0
        for b in range(g + 1):
            if not self.valid[b] or not np.isfinite(cost[b]).any():
                continue
            self.reach = b
            if b > 0:
                tc, td = self._costs(b, cost[b], True, g)
                if tc[0] < cost[b, 0]:
                    cost[b, 0], pred[b, 0] = tc[0], td[0]
            if b == g:
                break
            tc, td = self._costs(b, cost[b], False, g)
            for e in np.flatnonzero(np.isfinite(tc)):
                c = b + e + 1
                if c <= g and tc[e] < cost[c, e + 1]:
                    cost[c, e + 1], pred[c, e + 1] = tc[e], td[e]
        if furthest:
            ends = np.flatnonzero(np.isfinite(cost[1:, 0]))
            return self._back(pred, int(ends[-1]) + 1, 0) if ends.size else []
        if not np.isfinite(cost[g, 0]):
            return None
        return self._back(pred, g, 0)

    def _back(self, pred, b, d, layers=None):
        out = []
        k = len(layers) - 1 if layers is not None else None
        while not (b == 0 and d == 0 and (k is None or k == 0)):
            out.append(b)
            p = pred[b, d] if layers is None else layers[k][b, d]
            b, d = b - d, int(p)
            if k is not None:
                k -= 1
        return out[::-1]

    def fixed_steps(self, steps: int):
        """The least-cost walk of exactly ``steps`` swings that ends with the feet together, or None."""
        H, n = self.hi, self.n
        cost = np.full((n, H + 1), np.inf)
        cost[0, 0] = 0.0
        preds = [None]
        self.reach = 0
        for k in range(steps):
            new = np.full((n, H + 1), np.inf)
            pred = np.full((n, H + 1), -1, np.int64)
            final = k == steps - 1
            for b in np.flatnonzero(np.isfinite(cost).any(axis=1)):
                if not self.valid[b]:
                    continue
                self.reach = max(self.reach, int(b))
                tc, td = self._costs(int(b), cost[b], True, int(b) if final else None)
                if tc[0] < new[b, 0]:
                    new[b, 0], pred[b, 0] = tc[0], td[0]
                if final:
                    continue
                tc, td = self._costs(int(b), cost[b], False, None)
                for e in np.flatnonzero(np.isfinite(tc)):
                    c = b + e + 1
                    if tc[e] < new[c, e + 1]:
                        new[c, e + 1], pred[c, e + 1] = tc[e], td[e]
            cost = new
            preds.append(pred)
            if not np.isfinite(cost).any():
                return None
        ends = np.flatnonzero(np.isfinite(cost[:, 0]))
        if not ends.size:
            return None
        g = int(ends[np.argmin(cost[ends, 0])])
        return self._back(None, g, 0, preds)

    def why_not(self, what: str) -> str:
        """The refusal: what stops the walk after the furthest foothold reached."""
        r, y = self.r, float(self.ys[self.reach])
        nxt = np.flatnonzero(self.rights > y)
        if nxt.size:
            j = int(nxt[0])
            ob = self.obs[j]
            need = (ob[-1, 0] - ob[0, 0]) + r.foot + 2.0 * (r.tolerance + r.stand)
            if self.too_many[j]:
                return (
                    f"{what}: {_describe(ob)} has {len(ob)} profile points, more than a swing's obstacle "
                    f"may have ({geometry.MAX_PROFILE_VERTICES - 2}); the walk stops at y = {y:.2f} m"
                )
            if need > r.hi + 1e-9:
                return (
                    f"{what}: no step can cross {_describe(ob)}: it needs a swing of at least {need:.2f} m "
                    f"(foot and clearances included), longer than the longest step ({r.hi:.2f} m); the walk "
                    f"stops at y = {y:.2f} m"
                )
            k0, clear = self.clears(j)
            if not clear.any():
                return (
                    f"{what}: no swing can clear {_describe(ob)}: the heel {r.lift * 100:.1f} cm above it is out "
                    f"of the leg's reach or joint limits for every stance position; the walk stops at "
                    f"y = {y:.2f} m"
                )
        ahead = np.flatnonzero(self.valid[self.reach + 1 :])
        if not ahead.size or ahead[0] + 1 > self.hi:
            gap_to = (
                f"the next is at y = {self.ys[self.reach + 1 + ahead[0]]:.2f} m"
                if ahead.size
                else "there is none"
            )
            return (
                f"{what}: no flat foothold within a step of y = {y:.2f} m ({gap_to}; the longest step is "
                f"{r.hi:.2f} m)"
            )
        ob = _describe(self.obs[int(nxt[0])]) if nxt.size else ""
        where = f" across {ob}" if ob and ob not in what else ""
        return (
            f"{what}: the walk gets no further than y = {y:.2f} m: no footholds with swings of "
            f"{r.lo:.2f}-{r.hi:.2f} m lead on from there{where}"
        )


# --------------------------------------------------------------------------------------------
# The walk
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CourseStep:
    """One swing of the walk: which leg, where it starts, pivots and lands (m), the checked path
    (``trajectory``), its device timing (``timed``, a TimedSwing) and when it runs in the walk (s)."""

    index: int
    leg: str
    start_y: float
    pivot_y: float
    goal_y: float  # the planned foothold
    landing_y: float  # where the heel came down
    flat: bool  # no obstacle under the swing (planned over FLAT_OBSTACLE)
    trajectory: Trajectory
    timed: object  # TimedSwing; None for a failed swing (not timed)
    start_s: float
    end_s: float

    @property
    def method(self) -> str:
        return self.trajectory.method

    @property
    def ok(self) -> bool:
        return self.trajectory.ok and self.timed is not None and self.timed.ok

    @property
    def reasons(self) -> tuple[str, ...]:
        out = tuple(self.trajectory.checks.reasons)
        return out + tuple(
            r for r in (self.timed.reasons if self.timed is not None else ()) if r not in out
        )


@dataclass(frozen=True)
class Course:
    """A planned walk: the footholds, each step, and the whole walk as one timed table of both legs
    (``table``, WALK_COLUMNS). ``ok``: every swing safe and within the device limits and every
    hand-over from one swing to the next continuous; ``reasons`` say which step failed and where."""

    terrain: Terrain
    footholds: Footholds
    steps: tuple[CourseStep, ...]
    rate: float
    limits: object
    double_support: float
    method: str
    samples: np.ndarray  # (T, len(WALK_COLUMNS))
    junction_jump: float  # rad, largest joint-angle jump at a hand-over
    reasons: tuple[str, ...]
    plan_seconds: float = 0.0
    notes: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return not self.reasons

    @property
    def duration(self) -> float:
        return float(self.samples[-1, 0]) if len(self.samples) else 0.0

    @property
    def methods(self) -> tuple[str, ...]:
        return tuple(s.method for s in self.steps)

    def table(self) -> np.ndarray:
        return self.samples

    def to_csv(self, path: str | Path | None = None) -> str:
        return write_csv(WALK_COLUMNS, self.samples, "{:.9g}", path)

    def to_dict(self) -> dict:
        steps = []
        for s in self.steps:
            d = timed_dict(s.timed) if s.timed is not None else s.trajectory.to_dict()
            samples = np.asarray(d["samples"])
            samples[:, 0] += s.start_s  # walk time
            d["samples"] = samples.tolist()
            d.update(
                {
                    "index": s.index,
                    "leg": s.leg,
                    "method": s.method,
                    "start_y": s.start_y,
                    "pivot_y": s.pivot_y,
                    "planned_landing_y": s.goal_y,
                    "landing": {"heel_y": s.landing_y, "heel_z": 0.0},
                    "flat": s.flat,
                    "start_s": s.start_s,
                    "end_s": s.end_s,
                    "ok": s.ok,
                    "reasons": list(s.reasons),
                }
            )
            steps.append(d)
        return {
            "units": {
                "length": "m",
                "angle": "rad",
                "time": "s",
                "joint velocity": "rad/s",
                "joint acceleration": "rad/s^2",
                "rate": "Hz",
            },
            "ok": self.ok,
            "reasons": list(self.reasons),
            "method": self.method,
            "terrain": {"source": self.terrain.source, "points": self.terrain.points.tolist()},
            "start_y": self.footholds.start_y,
            "footholds": list(self.footholds.landings),
            "rate_hz": self.rate,
            "duration_s": self.duration,
            "limits": self.limits.to_dict(),
            "double_support_s": self.double_support,
            "junction_jump_rad": self.junction_jump,
            "plan_seconds": self.plan_seconds,
            "notes": list(self.notes),
            "columns": list(WALK_COLUMNS),
            "samples": self.samples.tolist(),
            "steps": steps,
        }

    def to_json(self, path: str | Path | None = None) -> str:
        return write_json(self.to_dict(), path)


def flat_obstacle(start: float, goal: float, foot: float, stand: float) -> geometry.Obstacle:
    """The virtual obstacle of a swing over flat ground: FLAT_OBSTACLE, centred in the room between
    the toe at the start and the goal (narrowed to fit)."""
    w, h = FLAT_OBSTACLE
    lo, hi = start + foot + stand, goal - stand
    w = min(w, 0.5 * (hi - lo))
    return geometry.Obstacle.rectangle(w, h, center_y=0.5 * (lo + hi))


def _swing_obstacle(obs, start, goal, r: FootholdRules):
    inside = [o for o in obs if o[0, 0] > start and o[-1, 0] < goal]
    if not inside:
        return flat_obstacle(start, goal, r.foot, r.stand), True
    return geometry.Obstacle.profile(np.concatenate(inside)), False


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
    from jaxexo.inference.cfftg import CFFTG
    from jaxexo.inference.generator import TrajectoryGenerator
    from jaxexo.inference.options import check_fallback
    from jaxexo.inference.swing_timing import DeviceLimits, time_swings

    t0 = _time.perf_counter()
    if not isinstance(generator, (TrajectoryGenerator, CFFTG)):
        raise CourseError(
            f"generator: expected a TrajectoryGenerator or CFFTG, got {type(generator).__name__}"
        )
    config = generator.config
    rl = isinstance(generator, TrajectoryGenerator)
    fallback = check_fallback(fallback)
    terrain = _as_terrain(terrain)
    ds = _check_number("double_support", double_support, 0.0)
    if ds > MAX_DOUBLE_SUPPORT:
        raise CourseError(f"double_support: at most {MAX_DOUBLE_SUPPORT:g} s, got {ds:g}")
    limits = DeviceLimits.from_config(config) if limits is None else limits
    gen = generator.at_clearance(clearance)
    plan = footholds(
        terrain, config, start_y=start_y, goal_y=goal_y, steps=steps, clearance=clearance
    )
    r = FootholdRules.of(config, clearance)
    obs = obstacles_of(terrain)
    feet = [plan.start_y, plan.start_y]  # heel y of the left and right foot
    trajs, meta, stopped = [], [], None
    for k in range(len(plan)):
        leg = k % 2
        start, pivot, goal = feet[leg], feet[1 - leg], plan.landings[k]
        ob, flat = _swing_obstacle(obs, start, goal, r)
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
    # A failed swing is not timed (its path may not be one a drive can follow).
    good = [t for t in trajs if t.ok]
    timed = time_swings(good, config, rate=rate, limits=limits, sp=gen.sp) if good else []
    rate = timed[0].rate if timed else float(config.device.control_rate if rate is None else rate)
    samples, spans, jump = _walk_table(timed, meta, ds, rate)
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
    if stopped is not None and stopped + 1 < len(plan):
        reasons.append(
            f"steps {stopped + 2}-{len(plan)} not planned: the walk cannot go on from a failed swing"
        )
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


def _walk_table(timed, meta, double_support: float, rate: float):
    """The whole walk as one table (WALK_COLUMNS): each swing's samples in walk time, the swing
    leg's columns on its side; a landing's pose held ``double_support`` s; the first sample of a
    swing (its lift-off, the same instant and pose as the landing before) kept once. Returns the
    table, each step's (start, end) in s, and the largest joint-angle jump at a hand-over (rad)."""
    rows, spans = [np.zeros((0, len(WALK_COLUMNS)))], []
    offset, jump = 0.0, 0.0
    last = None
    for t, (k, leg, start, pivot, goal, land, flat) in zip(timed, meta):
        n = len(t.time)
        side = LEGS.index(leg)
        block = np.zeros((n, len(WALK_COLUMNS)))
        block[:, 0] = t.time + offset
        block[:, 1] = k + 1
        block[:, 2] = side
        stance = np.zeros_like(t.heel)
        stance[:, 0] = pivot
        feet = [None, None]
        feet[side], feet[1 - side] = t.heel, stance
        for i, h in enumerate(feet):
            block[:, 3 + 4 * i : 5 + 4 * i] = h
            block[:, 5 + 4 * i] = h[:, 0] + (t.toe[0, 0] - t.heel[0, 0])
            block[:, 6 + 4 * i] = h[:, 1]
        block[:, 11:13] = t.hip
        knees = [None, None]
        knees[side], knees[1 - side] = t.knee_swing, t.knee_stance
        block[:, 13:15], block[:, 15:17] = knees
        for base, arr in ((17, t.joint_angles), (21, t.joint_velocity), (25, t.joint_acceleration)):
            sw, st = arr[:, 0:2], arr[:, 2:4]
            block[:, base + 2 * side : base + 2 * side + 2] = sw
            block[:, base + 2 * (1 - side) : base + 2 * (1 - side) + 2] = st
        if last is not None:
            jump = max(jump, float(np.abs(block[0, 17:21] - last[17:21]).max()))
            block = block[1:]
        if last is not None and double_support > 0.0:
            m = max(1, int(round(double_support * rate)))
            hold = np.repeat(last[None], m, axis=0)
            hold[:, 0] = last[0] + np.arange(1, m + 1) / rate
            hold[:, 2] = -1
            hold[:, 21:] = 0.0
            rows.append(hold)
            offset += m / rate
            block[:, 0] += m / rate
        spans.append((offset, offset + float(t.time[-1])))
        rows.append(block)
        offset += float(t.time[-1])
        last = block[-1]
    return np.concatenate(rows), spans, jump


__all__ = [
    "Course",
    "CourseError",
    "CourseStep",
    "Footholds",
    "FootholdRules",
    "Terrain",
    "WALK_COLUMNS",
    "footholds",
    "obstacles_of",
    "plan_course",
    "flat_obstacle",
    "read_terrain",
]
