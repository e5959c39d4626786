"""The course's ground and the numbers a walk is bound by: the terrain's obstacles (``obstacles_of``),
the rules footholds are chosen by (``FootholdRules``), the virtual obstacle of a swing over flat
ground, and ``CourseError``, the refusal that names the position along the course."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from jaxexo.physics import geometry
from jaxexo.physics.terrain import NEAR_MARGIN
from jaxexo.storage.terrain_file import Terrain

GRID = 0.01  # m, foothold resolution
STAND_MARGIN = (
    NEAR_MARGIN  # m, least distance of a standing foot from an obstacle (the training's toe margin)
)
FLAT_OBSTACLE = (
    0.10,
    0.03,
)  # m, (width, height) of the virtual obstacle a swing on flat ground lifts over
MAX_STEPS = 1000  # swings in one walk (``steps``)
MAX_DOUBLE_SUPPORT = 10.0  # s


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


def describe(ob: np.ndarray) -> str:
    return f"the obstacle at y = {ob[0, 0]:.2f}-{ob[-1, 0]:.2f} m ({_height(ob[:, 1].max())})"


def _height(h: float) -> str:
    """An obstacle's height in words: cm, or mm below 1 cm, where a floor measured with noise is
    refused (the terrain file's rule: the floor is z = 0 exactly, anything above it an obstacle)."""
    if h >= 0.01:
        return f"{h * 100:.0f} cm high"
    return (
        f"{h * 1000:.2g} mm high; the floor is z = 0 exactly and any point above it is an "
        "obstacle: write a measured floor as 0"
    )


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


def check_number(name: str, v, lo=None, integer=False):
    if v is None:
        return None
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise CourseError(f"{name}: expected a number, got {v!r}")
    bound = "" if lo is None else f" >= {lo:g}"
    if not math.isfinite(float(v)):
        raise CourseError(f"{name}: must be a finite number{bound}, got {float(v)!r}")
    if integer and int(v) != v:
        raise CourseError(f"{name}: expected a whole number, got {v!r}")
    v = int(v) if integer else float(v)
    if lo is not None and v < lo:
        raise CourseError(f"{name}: must be a finite number{bound}, got {geometry.as_given(v)}")
    return v


def check_double_support(name: str, v) -> float:
    """The double support (s) between two swings: 0 to MAX_DOUBLE_SUPPORT."""
    ds = check_number(name, v, 0.0)
    if ds > MAX_DOUBLE_SUPPORT:
        raise CourseError(f"{name}: at most {MAX_DOUBLE_SUPPORT:g} s, got {geometry.as_given(ds)}")
    return ds


def flat_obstacle(start: float, goal: float, foot: float, stand: float) -> geometry.Obstacle:
    """The virtual obstacle of a swing over flat ground: FLAT_OBSTACLE, centred in the room between
    the toe at the start and the goal (narrowed to fit)."""
    w, h = FLAT_OBSTACLE
    lo, hi = start + foot + stand, goal - stand
    w = min(w, 0.5 * (hi - lo))
    return geometry.Obstacle.rectangle(w, h, center_y=0.5 * (lo + hi))


# --------------------------------------------------------------------------------------------
# The walk's size, before any swing is planned
# --------------------------------------------------------------------------------------------

# Bytes a walk holds per sample row (WALK_COLUMNS) at its peak: measured on a 24 s walk at 1 kHz,
# 1.5 KB with its swings timed and the CSV written, 10.5 KB with the JSON too (its lists and text
# are built whole, with every step's own samples); rounded up.
ROW_BYTES = 2048
JSON_ROW_BYTES = 12 * 1024


@dataclass(frozen=True)
class WalkSize:
    """A walk's size estimated before any swing is planned: the course from ``start`` to ``goal``
    (m), the fewest swings that cover it, a lower bound on its duration (s) and its samples
    (rows of WALK_COLUMNS) at ``rate`` (Hz)."""

    start: float
    goal: float
    swings: int
    duration: float
    rows: int
    rate: float


def _least_swing(r: FootholdRules, limits, step: float) -> float:
    """A lower bound on the time (s) of a swing of ``step`` m over flat ground, pivoting midway:
    each joint's move from the lift-off pose to the landing pose at rest at both ends, as fast as
    its velocity and acceleration limits allow (bang-bang), and the limits' minimum duration."""
    from jaxexo.swing.timing import leg_angles

    q = leg_angles(r, 0.5 * step, np.array([[0.0, 0.0], [step, 0.0]]))
    dq = np.abs(q[1] - q[0])
    v, a = np.asarray(limits.velocity), np.asarray(limits.acceleration)
    t = np.where(dq <= v * v / a, 2.0 * np.sqrt(dq / a), dq / v + v / a)
    return max(float(t.max()), limits.min_duration)


def walk_size(
    terrain, config, r: FootholdRules, *, limits, rate, start_y, goal_y, steps, dwell
) -> WalkSize:
    """``WalkSize`` of a walk over ``terrain`` (numbers as ``plan_course`` takes them, not yet
    checked): the course from ``start_y`` (default: its first point) to ``goal_y`` (default: the
    last place a foot can land), crossed in ``steps`` swings or at least 2 L / (longest swing) (each
    foot covers L, a swing moves one foot at most r.hi), each at least ``_least_swing`` of the
    longest swing (the bound per metre is least there), ``dwell`` s at each landing. Cheap: no
    search, no swing."""
    y = terrain.y
    start = float(y[0]) if start_y is None else float(start_y)
    goal = float(y[-1]) - r.foot - r.tolerance if goal_y is None else float(goal_y)
    if steps is None:
        swings = max(1, math.ceil(2.0 * max(goal - start, 0.0) / r.hi - 1e-9))
    else:
        swings = int(steps)
    rate = float(config.device.control_rate if rate is None else rate)
    least = swings * _least_swing(r, limits.planned(), r.hi) + (swings - 1) * max(dwell, 0.0)
    return WalkSize(
        start=start, goal=goal, swings=swings, duration=least, rows=int(least * rate) + 1, rate=rate
    )


def check_walk_size(
    size: WalkSize, *, columns: int, row_bytes: int, names: dict, known: bool = False
) -> None:
    """Refuse (CourseError) a walk whose samples (rows of ``columns``) at ``row_bytes`` each exceed
    half the memory this process may use (jaxexo.config.memory.process_memory_bytes), naming the
    rate and the course by ``names`` ("rate", "course", "outputs": as the caller's user typed
    them); ``known``: the rows are counted, not estimated."""
    from jaxexo.config.memory import process_memory_bytes

    room = process_memory_bytes()
    need = size.rows * row_bytes
    if need <= room // 2:
        return
    what = "takes" if known else "takes at least"
    raise CourseError(
        f"{names['rate']}: a walk of {size.swings} swings over {size.goal - size.start:.2f} m of "
        f"course (y = {size.start:.2f} to {size.goal:.2f} m) at {size.rate:g} Hz {what} "
        f"{size.duration:.1f} s: {'' if known else 'at least '}{size.rows:,} samples x "
        f"{columns} columns, about {need / 2**30:.2f} GiB{names['outputs']}, more than "
        f"half the memory this process may use ({room / 2**30:.2f} GiB); lower {names['rate']} "
        f"or walk a shorter course ({names['course']})"
    )
