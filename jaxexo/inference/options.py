"""The options shared by every generator (the RL policy, CFFTG): scene defaults and checks.

A swing is asked for by an obstacle and where the feet are: the pivot (stance) heel, the swing
heel's start and the step length; their defaults are jaxexo.physics.dynamics's (DEFAULT_PIVOT,
DEFAULT_START_Y, DEFAULT_STEP_LENGTH). ``scenes_for`` turns the per-obstacle options of
``generate_batch`` into validated scenes (jaxexo.physics.dynamics.make_scene); ``check_options``
bounds the sizes taken from input.
"""

from __future__ import annotations

import numpy as np

from jaxexo.config import MAX_SWING_DURATION
from jaxexo.physics import geometry
from jaxexo.physics.dynamics import DEFAULT_PIVOT, DEFAULT_START_Y, DEFAULT_STEP_LENGTH, Scene, make_scene

# Bounds of the sizes taken from input, checked before anything is allocated.
MAX_POINTS = 100_000                 # samples of one path
MAX_DURATION = MAX_SWING_DURATION    # s: a swing, not a walk (jaxexo.config)
# Fewer samples cannot follow a swing over an obstacle: with 2-10 the checks judged the path between
# them with clearances and backward moves of metres.
MIN_POINTS = 20
# s: no joint drive swings a leg in less (below about 1e-4 s the CSV's time column read all zeros).
MIN_DURATION = 0.01

FALLBACKS = ("cfftg", None)


def pivot_of(pivot, pivot_y):
    """The scene's pivot: a condition (default DEFAULT_PIVOT) or ``pivot_y`` in metres, not both."""
    if pivot_y is None:
        return DEFAULT_PIVOT if pivot is None else pivot
    if pivot is not None:
        raise ValueError(f"pivot, pivot_y: give one of them (a condition or a y in metres), got pivot={pivot!r} "
                         f"and pivot_y={pivot_y!r}")
    return pivot_y


def scene_for(config, obstacle, pivot=None, pivot_y=None, start_y=DEFAULT_START_Y,
              step_length=DEFAULT_STEP_LENGTH) -> Scene:
    """One validated scene (metres) for a generator of ``config`` (its foot length and shape
    descriptor); ``pivot_y``, when given, replaces the ``pivot`` condition."""
    return make_scene(obstacle, pivot_of(pivot, pivot_y), start_y, step_length,
                      foot_length=config.kinematics.foot_length, shape_points=config.env.shape_points)


def scenes_for(make, obstacles, pivot, pivot_y, start_y, step_length) -> list[Scene]:
    """Scenes for many obstacles with ``make(obstacle, pivot, pivot_y, start_y, step_length)``; every
    option is one value for all or one per obstacle (every generator's generate_batch)."""
    if isinstance(obstacles, geometry.Obstacle):
        raise TypeError("obstacles: expected a list of Obstacle objects, got one Obstacle (use generate() for "
                        "one scenario, or pass [obstacle])")
    try:
        obstacles = list(obstacles)
    except TypeError:
        raise TypeError(f"obstacles: expected a list of Obstacle objects, got {type(obstacles).__name__}") from None
    n = len(obstacles)
    if n == 0:
        raise ValueError("obstacles: need at least one scenario")

    def per(name, v):
        if np.ndim(v) == 0 or isinstance(v, str):
            return [v] * n
        v = list(v)
        if len(v) != n:
            raise ValueError(f"{name}: {len(v)} values for {n} obstacles")
        return v

    return [make(o, p, py, s, sl) for o, p, py, s, sl in zip(
        obstacles, per("pivot", pivot), per("pivot_y", pivot_y), per("start_y", start_y),
        per("step_length", step_length))]


def check_points(n_points, name: str = "n_points") -> int:
    """Samples of a path: an integer in [MIN_POINTS, MAX_POINTS]; ValueError naming ``name``."""
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or not (
            MIN_POINTS <= n_points <= MAX_POINTS):
        raise ValueError(f"{name} must be an integer in [{MIN_POINTS}, {MAX_POINTS}], got {n_points!r}")
    return int(n_points)


def check_duration(duration, name: str = "duration") -> float:
    """A swing's duration in [MIN_DURATION, MAX_DURATION] s; ValueError naming ``name``."""
    duration = geometry.finite_positive(name, duration, "s")
    if duration > MAX_DURATION:
        raise ValueError(f"{name} must be <= {MAX_DURATION:g} s (one swing), got {duration:g}")
    if duration < MIN_DURATION:
        raise ValueError(f"{name} must be >= {MIN_DURATION:g} s (no drive swings a leg faster), got {duration:g}")
    return duration


def check_flag(value, name: str) -> bool:
    """A yes/no option: True or False only (``strict="yes"`` or ``fast="no"`` would be taken as true)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}: expected True or False, got {value!r}")
    return bool(value)


def check_options(n_points, smoothing, duration):
    """(n_points, smoothing m^2, duration s) checked: ValueError naming the option."""
    n_points = check_points(n_points)
    smoothing = geometry.finite("smoothing", smoothing, "m^2")
    if smoothing < 0:
        raise ValueError(f"smoothing must be >= 0 (m^2), got {smoothing}")
    return n_points, smoothing, check_duration(duration)


def check_fallback(fallback):
    """"cfftg" or None ("none" from a command line)."""
    if fallback == "none":
        return None
    if fallback not in FALLBACKS:
        raise ValueError(f"fallback must be 'cfftg' or None, got {fallback!r}")
    return fallback
