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


def flat_obstacle(start: float, goal: float, foot: float, stand: float) -> geometry.Obstacle:
    """The virtual obstacle of a swing over flat ground: FLAT_OBSTACLE, centred in the room between
    the toe at the start and the goal (narrowed to fit)."""
    w, h = FLAT_OBSTACLE
    lo, hi = start + foot + stand, goal - stand
    w = min(w, 0.5 * (hi - lo))
    return geometry.Obstacle.rectangle(w, h, center_y=0.5 * (lo + hi))
