"""Where the feet land: ``footholds`` chooses a walk's footholds on the course before any swing is
planned (jaxexo.course, 1.), ``Footholds`` holds them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from jaxexo.course.ground import (
    GRID,
    MAX_STEPS,
    CourseError,
    FootholdRules,
    check_number,
    describe,
    obstacles_of,
)
from jaxexo.course.search import Planner
from jaxexo.physics import geometry
from jaxexo.storage.terrain_file import Terrain


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


def _given(y: float) -> str:
    """A position the caller gave, to the millimetre as the course's are, or exactly where that
    would round it (4.7004 m is not 4.700 m, the end it is refused against)."""
    text = f"{y:.3f}"
    return text if float(text) == y else geometry.as_given(y)


def footholds(
    terrain: Terrain,
    config,
    *,
    start_y: float | None = None,
    goal_y: float | None = None,
    steps: int | None = None,
    clearance: float | None = None,
) -> Footholds:
    """Choose the footholds of a walk over ``terrain`` (jaxexo.course, 1.): from ``start_y``
    (default: the terrain's first point) to ``goal_y`` (default: the furthest foothold the terrain
    allows), or, with ``steps``, the walk of exactly that many swings. CourseError naming the
    position when no walk exists."""
    if steps is not None and goal_y is not None:
        raise CourseError("goal_y, steps: give one of them (where to go, or how many swings)")
    steps = check_number("steps", steps, 1, integer=True)
    if steps is not None and steps > MAX_STEPS:
        raise CourseError(f"steps: at most {MAX_STEPS} swings, got {steps}")
    r = FootholdRules.of(config, clearance)
    obs = obstacles_of(terrain)
    y0, y_end = float(terrain.y[0]), float(terrain.y[-1])
    start = y0 if start_y is None else check_number("start_y", start_y)
    if not y0 <= start <= y_end - r.foot:
        raise CourseError(
            f"start_y: {_given(start)} m is not on the course (the foot must stand between "
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
            f"clear of {describe(obs[blocked])}"
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
        goal_y = check_number("goal_y", goal_y)
        g = int(round((goal_y - start) / GRID))
        if g <= 0:
            raise CourseError(
                f"goal_y: {_given(goal_y)} m must lie ahead of the start ({start:.3f} m)"
            )
        if g >= n:
            raise CourseError(
                f"goal_y: {_given(goal_y)} m is beyond the last place a foot can land on the course "
                f"({ys[-1]:.3f} m: the terrain ends at {y_end:.3f} m)"
            )
        if not valid[g]:
            raise CourseError(
                f"goal_y: a foot at y = {ys[g]:.3f} m does not stand on flat ground clear of "
                f"{describe(obs[over[g]])}"
            )
    planner = Planner(r, ys, valid, obs, lefts, rights)
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
                planner.why_not(f"no walk gets past {describe(obs[int(left_out[0])])}")
            )
    return Footholds(float(start), tuple(float(ys[k]) for k in path))


def _overlapping(lefts, rights, lo, hi) -> np.ndarray:
    """For each window (lo, hi) (m): the index of an obstacle reaching into it, or -1."""
    if lefts.size == 0:
        return np.full(len(lo), -1)
    i = np.searchsorted(lefts, hi, side="left")  # obstacles starting before the window's end ...
    j = np.searchsorted(rights, lo, side="right")  # ... less those ending at or before its start
    return np.where(i > j, j, -1)
