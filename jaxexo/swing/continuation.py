"""Continuation paths (NumPy only): what both generators check before planning a heel path from a
mid-air foot state (jaxexo.swing.replan.FootState) over a new obstacle to the same goal, and the
policy's clock at that state (the step count and the mid-goal flag its path so far implies).
Method: docs/replanning.md (Continuation paths).
"""

from __future__ import annotations

import numpy as np

from jaxexo.physics import geometry, transition
from jaxexo.swing.replan import FootState

# m: the path so far must begin where the scene's swing does (lift-off at (start_y, 0)); the curve's
# heel at s = 0 is its joint spline's forward kinematics, equal to the start up to rounding.
START_TOL = 1e-6
# m: the new scene's pivot, start and goal must be the swing's (a scene laid out from the same feet
# gives the same numbers; this only forgives rounding).
FEET_TOL = 1e-9


def _vector(name: str, value, shape: tuple) -> np.ndarray:
    """A finite float64 array of ``shape`` (None: any length on that axis); ValueError naming it."""
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != len(shape) or any(w is not None and n != w for n, w in zip(a.shape, shape)):
        want = "(" + ", ".join("P" if w is None else str(w) for w in shape) + ")"
        raise ValueError(f"state.{name}: expected shape {want}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"state.{name}: must be finite, got {value!r}")
    return a


def check_state(state, scene, sp, swing_scene=None) -> FootState:
    """The foot's state checked against the new ``scene`` for constants ``sp`` (at the swing's
    clearance): a FootState whose heel, velocity and acceleration are finite (2,) vectors and whose
    path so far (P, 2) starts at the scene's start on the floor; with ``swing_scene`` (the scene the
    swing was planned on) the new scene must keep its pivot, start and goal. A foot already within
    env.min_clearance of the new obstacle is refused: no continuation from there keeps the margin.
    ValueError (TypeError for a state that is not a FootState) naming what is wrong."""
    if not isinstance(state, FootState):
        raise TypeError(
            f"state: expected a FootState (jaxexo.swing.replan), got {type(state).__name__}"
        )
    heel = _vector("heel", state.heel, (2,))
    _vector("heel_velocity", state.heel_velocity, (2,))
    _vector("heel_acceleration", state.heel_acceleration, (2,))
    past = _vector("past_heel", state.past_heel, (None, 2))
    if len(past) == 0:
        raise ValueError("state.past_heel: the heel's path so far needs at least one point")
    if swing_scene is not None:
        for name in ("pivot_y", "start_y", "goal_y"):
            new, old = float(getattr(scene, name)), float(getattr(swing_scene, name))
            if abs(new - old) > FEET_TOL:
                raise ValueError(
                    f"scene: its {name} ({new!r} m) is not the swing's ({old!r} m); a continuation "
                    "keeps the swing's feet (pivot, start and goal) and changes only the obstacle"
                )
    y0, z0 = past[0]
    if abs(y0 - scene.start_y) > START_TOL or abs(z0) > START_TOL:
        raise ValueError(
            f"state.past_heel: starts at (y={y0:.6f}, z={z0:.6f}) m, not at the scene's start "
            f"(y={scene.start_y:.6f}, z=0) m: the state is not of a swing from this scene's start"
        )
    if heel[1] < 0.0:
        raise ValueError(f"state.heel: below the ground (z={heel[1]!r} m)")
    c = float(geometry.foot_clearance(np, heel[None], sp.foot_length, scene.outline)[0])
    if c < sp.min_clearance:
        raise ValueError(
            f"state: the foot (heel y={heel[0]:.4f} m, z={heel[1]:.4f} m) is already "
            f"{'inside' if c < 0 else f'{c:.4f} m from'} the new obstacle, within the margin "
            f"env.min_clearance = {sp.min_clearance:.4f} m: no continuation from there is safe"
        )
    return state


def policy_clock(state: FootState, scene, sp, max_steps: int) -> tuple[int, bool]:
    """(steps, visited): the policy's step count at the state, its path so far's arc length over the
    step size rounded (clipped to max_steps - 1, so that one move is left), and whether any point of
    that path lies in the new scene's mid-goal box (transition.in_mid_goal)."""
    past = np.asarray(state.past_heel, np.float64)
    d = np.diff(past, axis=0)
    length = float(np.sqrt((d * d).sum(axis=1)).sum())
    steps = min(int(round(length / float(sp.step_size))), int(max_steps) - 1)
    mid_y, mid_z = transition.mid_goal(np, sp, scene.center_y, scene.height)
    visited = bool(np.any(transition.in_mid_goal(np, sp, past[:, 0], past[:, 1], mid_y, mid_z)))
    return steps, visited
