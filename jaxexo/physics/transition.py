"""The environment's transition rules (thesis 2.1-2.5), written once for every array module ``xp``:
``numpy``, ``jax.numpy`` or ``scalar`` below (plain Python floats, the generator's one-swing loop
and the shield's scalar form). ``step`` sequences one step for every stepper: the JAX environment,
the NumPy generator's rollouts and the thesis-style NumPy environment. Heel coordinates come as
separate y and z so that one code serves a scalar, a batch and a traced value. ``p``: the parameter
views of jaxexo.config (``param_values``); ``layout``: the Scene/Layout fields. Design:
docs/architecture.md.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

from jaxexo.physics import geometry, kinematics, rewards, swept


class _Scalar:
    """A scalar "array module" for the generator's per-step loop on Python floats: the few functions
    the transition rules below use, with numpy's meaning."""

    __slots__ = ()
    minimum, maximum, abs, sqrt = map(staticmethod, (min, max, abs, math.sqrt))
    # a conditional expression, three times faster than min/max
    clip = staticmethod(lambda x, lo, hi: lo if x < lo else (hi if x > hi else x))
    where = staticmethod(lambda c, a, b: a if c else b)


scalar = _Scalar()


class StepInfo(NamedTuple):
    """A scored step's diagnostics (``[...]``: the batch's shape, () for one environment)."""

    traj_terms: Any  # [..., 8] the trajectory terms, rewards.TRAJECTORY_TERMS (eq 2.29-2.37)
    exo_terms: Any  # [..., 4] the exoskeleton terms, rewards.EXO_TERMS (eq 2.43-2.51)
    wearer_terms: Any  # [..., 3] the wearer's costs, rewards.WEARER_TERMS
    shaping: Any  # [...] the progress shaping reward
    clearance: Any  # [...] m, the swept clearance of the move (<= 0: touched)
    collision: Any  # [...] bool
    goal_reached: Any  # [...] bool
    joint_limit_violation: Any  # [...] bool
    leg_length_violation: Any  # [...] bool
    joint_angles: Any  # [..., 4] rad, both legs' hip and knee (kinematics.both_legs_angles)
    heel: Any  # [..., 2] m, the swing heel (y, z) after the move
    hip: Any  # [..., 2] m
    backward: (
        Any  # [...] m the heel is behind its furthest y so far (eq 2.31; the safe-swing measure)
    )


class Step(NamedTuple):
    """One step of an episode (``[...]``: the batch's shape; Python floats and bools in the scalar
    form). ``reward``, ``info`` and ``max_y`` are None for an unscored step (``step``'s
    ``collides``)."""

    heel_y: Any  # [...] m, the heel after the move
    heel_z: Any  # [...] m
    time: Any  # [...] steps taken after it
    visited_mid: Any  # [...] bool: the heel has passed through the mid-goal box
    terminated: Any  # [...] bool: the goal, or a collision that ends the episode (thesis 2.2)
    truncated: Any  # [...] bool: the step limit, from the step count alone (gymnax's)
    reward: Any  # [...] eq 2.1-2.2 with the shaping and the wearer's costs
    info: StepInfo | None
    max_y: Any  # [...] m, the heel's largest y so far, for the next step


def move_heel(xp, p, heel_y, heel_z, dir_y, dir_z):
    """One action: the heel moves step_size along its direction, kept inside the world."""
    return keep_in_world(xp, p, heel_y + p.step_size * dir_y, heel_z + p.step_size * dir_z)


def keep_in_world(xp, p, y, z):
    """The point (y, z) clipped into the world: above the ground, below max_z, within bounds_y."""
    return xp.clip(y, p.bounds_y[0], p.bounds_y[1]), xp.clip(z, 0.0, p.max_z_world)


# m: a move shorter than this along both axes does not move the heel. Only a vertical move at the
# ground or a bound is ever that short (any other move keeps >= step_size * sin(10 deg) of its length
# along y), so the threshold decides nothing else; it makes the rule indifferent to a heel a few ulps
# above the ground (float32 and float64 rollouts of one swing agree).
MOVE_EPS = 1e-6


def moves_heel(xp, heel_y, heel_z, ends):
    """(..., F) bool: the forward moves whose end ``ends`` (..., F, 2) is not the heel itself (a move
    into the ground, or past the world's bounds, that ``move_heel``'s clipping cancels)."""
    return heel_moved(xp, heel_y[..., None], heel_z[..., None], ends[..., 0], ends[..., 1])


def heel_moved(xp, heel_y, heel_z, end_y, end_z):
    """``moves_heel`` for ends given by their y and z (broadcast with the heel's)."""
    return (xp.abs(end_y - heel_y) > MOVE_EPS) | (xp.abs(end_z - heel_z) > MOVE_EPS)


def move_clearance(xp, p, prev, heel, outline):
    """Signed clearance (m) of the whole move from heel ``prev`` to ``heel`` (..., 2) against
    ``outline`` (..., K, 2): the region the flat foot sweeps (jaxexo.physics.swept), so that a move
    cannot jump through a corner of the obstacle. The one collision test of ``step``: the JAX environment
    and the NumPy rollouts (jaxexo.inference) end a colliding episode on it
    (``geometry.foot_collides``) at the same step."""
    return swept.swept_clearance(xp, prev, heel, p.foot_length, outline)


def terminated(xp, reached, collided, collision_ends):
    """An episode ends at the goal, or at a collision when ``collision_ends`` (thesis 2.2)."""
    return reached | (collided & collision_ends)


def truncated(time, max_steps):
    """The step limit: ``time`` steps taken of at most ``max_steps`` (gymnax's truncation, from the
    step count alone, even on a step that also terminates)."""
    return time >= max_steps


def mid_goal(xp, p, center_y, height):
    """Centre (y, z) of the mid-goal box (thesis 2.2): above the obstacle centre, at a safe height."""
    return center_y, height + p.mid_goal_clearance


def in_mid_goal(xp, p, heel_y, heel_z, mid_y, mid_z):
    return (xp.abs(heel_y - mid_y) <= p.mid_goal_half_size[0]) & (
        xp.abs(heel_z - mid_z) <= p.mid_goal_half_size[1]
    )


def beyond_mid_goal(xp, p, heel_y, mid_y):
    """The heel has passed the mid-goal box's far side (eq 2.33 fires if it never went through)."""
    return heel_y > mid_y + p.mid_goal_half_size[0]


def in_goal_column(xp, p, heel_y, goal_y):
    """The heel is above or in the goal box: |y - goal| <= goal_tolerance[0]."""
    return xp.abs(heel_y - goal_y) <= p.goal_tolerance[0]


def goal_reached(xp, p, heel_y, heel_z, goal_y):
    """The heel is back on the ground at the goal (eq 2.32): in the goal column, z <= goal_tolerance[1]."""
    return in_goal_column(xp, p, heel_y, goal_y) & (heel_z <= p.goal_tolerance[1])


def keeps_off_floor(xp, p, heel_y, heel_z, goal_y):
    """The shield's floor rule: a heel at (y, z) is at least ``p.floor_clearance`` above the floor, or
    in the goal column (where it lands). 0 keeps every heel (the rule off)."""
    return (heel_z >= p.floor_clearance) | in_goal_column(xp, p, heel_y, goal_y)


def never(*_):
    """``step``'s ``collides`` where collisions do not end an episode."""
    return False


def step(
    xp,
    p,
    heel_y,
    heel_z,
    direction,
    time,
    visited_mid,
    layout,
    *,
    max_steps,
    collides=None,
    max_y=None,
    action=None,
    last_action=None,
) -> Step:
    """One step of an episode (thesis 2.1-2.5), the one sequence of every stepper: the move along
    ``direction`` (its y and z [...] at [0] and [1]) from the heel (heel_y, heel_z) [...], its collision, the mid-goal, the goal, the
    reward and the termination. ``time`` is the step count before the move, ``visited_mid`` whether
    the mid-goal was visited before it, ``max_y`` the heel's largest y so far (None: the heel's y).

    ``collides`` None scores the step (the JAX and the thesis-style environments): collision and
    clearance of the whole move (jaxexo.physics.swept: the region the flat foot sweeps, so that a
    move cannot jump through a corner of the obstacle), the reward terms and the info (``score``,
    with ``action`` and ``last_action`` for the turn cost; None: no turn is counted). The NumPy
    rollouts, which need only where an episode ends, give ``collides(layout, prev_y, prev_z, y, z)``:
    the same swept collision of the moves a collision ends (cheap bounds before the exact test), or
    ``never``; their step has no reward."""
    y, z = move_heel(xp, p, heel_y, heel_z, direction[0], direction[1])
    time = time + 1
    if collides is None:
        prev, heel = xp.stack([heel_y, heel_z], axis=-1), xp.stack([y, z], axis=-1)
        clearance = move_clearance(xp, p, prev, heel, layout.outline)
        collided = geometry.foot_collides(xp, clearance)
    else:
        collided = collides(layout, heel_y, heel_z, y, z)
    mid_y, mid_z = mid_goal(xp, p, layout.center_y, layout.height)
    visited = visited_mid | in_mid_goal(xp, p, y, z, mid_y, mid_z)
    reached = goal_reached(xp, p, y, z, layout.goal_y)
    ends = p.terminate_on_collision if collides is None else True
    out = Step(
        heel_y=y,
        heel_z=z,
        time=time,
        visited_mid=visited,
        terminated=terminated(xp, reached, collided, ends),
        truncated=truncated(time, max_steps),
        reward=None,
        info=None,
        max_y=None,
    )
    if collides is not None:
        return out
    run_max = xp.maximum(heel_y if max_y is None else max_y, heel_y)
    no_turn = action is None or last_action is None
    turn = None if no_turn else rewards.turn_of(xp, p.directions, action, last_action)
    reward, info = score(
        xp,
        p,
        prev,
        heel,
        out,
        visited_mid=visited_mid,
        clearance=clearance,
        reached=reached,
        mid=(mid_y, mid_z),
        layout=layout,
        run_max=run_max,
        turn=turn,
    )
    return out._replace(reward=reward, info=info, max_y=xp.maximum(run_max, y))


def score(
    xp, p, prev, heel, out, *, visited_mid, clearance, reached, mid, layout, run_max, turn
) -> tuple[Any, StepInfo]:
    """The reward [...] and info of ``step``'s move from heel ``prev`` to ``heel`` [..., 2], as
    ``out`` (the step's flags: a Step), ``clearance`` (m), ``reached`` (the goal) and the
    mid-goal centre ``mid`` decided: the 8 + 4 reward terms (eq 2.29-2.52), the wearer's costs
    (rewards.wearer_terms, ``turn`` the turn's cost or None), the optional shaping, and the
    per-step diagnostics the one safe-swing verdict reads (jaxexo.physics.outcome.accumulate).
    ``run_max``: the heel's furthest y before the move."""
    lay, (mid_y, mid_z) = layout, mid
    collided = geometry.foot_collides(xp, clearance)
    kin = kinematics.leg_state(xp, lay.pivot_y, heel, p.thigh, p.shin)
    angles = kinematics.both_legs_angles(xp, kin)
    angles_prev = kinematics.both_legs_angles(
        xp, kinematics.leg_state(xp, lay.pivot_y, prev, p.thigh, p.shin)
    )
    limits_violated = kinematics.legs_outside_limits(xp, angles, p.hip_limits, p.knee_limits)
    traj = rewards.trajectory_terms(
        xp,
        p,
        steps=out.time,
        prev_heel=prev,
        heel=heel,
        collided=collided,
        clearance=clearance,
        reached_goal=reached,
        missed_mid=beyond_mid_goal(xp, p, heel[..., 0], mid_y) & ~out.visited_mid,
        mid_y=mid_y,
        max_z=lay.height + p.max_height_margin,
    )
    exo = rewards.exo_terms(
        xp,
        p,
        hip_z=kin.hip[..., 1],
        leg_swing=kin.leg_swing,
        leg_stance=kin.leg_stance,
        limits_violated=limits_violated,
    )
    wearer = rewards.wearer_terms(
        xp, p, heel=heel, top=lay.height, angles_prev=angles_prev, angles=angles, turn=turn
    )
    mid_goal_at = xp.stack([mid_y, mid_z], axis=-1)
    goal = xp.stack([lay.goal_y, 0.0 * lay.goal_y], axis=-1)
    shaping = rewards.shaping_reward(
        xp,
        p,
        rewards.progress_potential(xp, prev, mid_goal_at, goal, visited_mid),
        rewards.progress_potential(xp, heel, mid_goal_at, goal, out.visited_mid),
        out.terminated,
    )
    reward = rewards.total_reward(xp, p, traj, exo, wearer) + shaping
    return reward, StepInfo(
        traj_terms=traj,
        exo_terms=exo,
        wearer_terms=wearer,
        shaping=shaping,
        clearance=clearance,
        collision=collided,
        goal_reached=reached,
        joint_limit_violation=limits_violated,
        leg_length_violation=exo[..., 1] < 0,
        joint_angles=angles,
        heel=heel,
        hip=kin.hip,
        backward=run_max - heel[..., 0],
    )
