"""The environment's transition rules (thesis 2.1-2.5), written once for every array module ``xp``:
``numpy``, ``jax.numpy`` or ``scalar`` below (plain Python floats, the generator's one-swing loop
and the shield's scalar form). The JAX environment, the NumPy generator and the thesis-style NumPy
environment step, test and judge the heel with these functions; heel coordinates come as separate y
and z so that one code serves a scalar, a batch and a traced value. ``p``: the parameter views of
jaxexo.config (``param_values``); ``layout``: the Scene/Layout fields. Design: docs/architecture.md.
"""

from __future__ import annotations

import math
import types

from jaxexo.physics import geometry, kinematics, rewards, swept

# A scalar "array module" for the generator's per-step loop on Python floats: the few functions the
# transition rules below use, with numpy's meaning.
scalar = types.SimpleNamespace(
    minimum=min,
    maximum=max,
    abs=abs,
    sqrt=math.sqrt,
    clip=lambda x, lo, hi: lo if x < lo else (hi if x > hi else x),  # min/max: three times slower
    where=lambda c, a, b: a if c else b,
)


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
    cannot jump through a corner of the obstacle. The one collision test of every step sequence: the
    JAX environment's ``transition`` and the NumPy rollouts (jaxexo.inference) end a colliding
    episode on it (``geometry.foot_collides``) at the same step."""
    return swept.swept_clearance(xp, prev, heel, p.foot_length, outline)


def terminated(xp, p, reached, collided):
    """An episode ends at the goal, or at a collision when collisions terminate (thesis 2.2)."""
    return reached | (collided & p.terminate_on_collision)


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


def transition(
    xp, p, prev, heel, time, visited_mid, layout, max_y=None, action=None, last_action=None
) -> dict:
    """Everything a step from heel ``prev`` to ``heel`` (..., 2) decides (thesis 2.1-2.5), for the
    JAX environment and the NumPy environment alike: collision, mid-goal, goal, kinematics, the 8 + 4
    reward terms (eq 2.29-2.52), the wearer's costs (rewards.wearer_terms), optional shaping, the
    reward and termination. ``time`` is the step count after the move, ``visited_mid`` whether the
    mid-goal was visited before it, ``max_y`` the heel's largest y so far (None: ``prev``'s y),
    ``action`` the move and ``last_action`` the one before it (-1: none; None: no turn is counted).

    Collision and clearance are those of the whole move (jaxexo.physics.swept: the region the flat
    foot sweeps from ``prev`` to ``heel``), so a move cannot jump through a corner of the obstacle.
    The per-step ``info`` feeds the one safe-swing verdict (jaxexo.physics.outcome.accumulate):
    ``clearance`` of the move, ``backward`` (how far the heel is behind its furthest y), the goal,
    joint-limit and leg-length flags.

    Returns ``{"visited_mid", "reward", "terminated", "info", "max_y"}`` with ``info`` the
    environment's per-step diagnostics (reward terms, clearance, collision, goal, limit and leg-length
    flags, backward, joint angles, heel, hip) and ``max_y`` the running maximum to pass to the next step."""
    lay = layout
    clearance = move_clearance(xp, p, prev, heel, lay.outline)
    collided = geometry.foot_collides(xp, clearance)
    run_max = xp.maximum(prev[..., 0] if max_y is None else max_y, prev[..., 0])
    mid_y, mid_z = mid_goal(xp, p, lay.center_y, lay.height)
    visited = visited_mid | in_mid_goal(xp, p, heel[..., 0], heel[..., 1], mid_y, mid_z)
    missed_mid = beyond_mid_goal(xp, p, heel[..., 0], mid_y) & ~visited
    reached = goal_reached(xp, p, heel[..., 0], heel[..., 1], lay.goal_y)

    kin = kinematics.leg_state(xp, lay.pivot_y, heel, p.thigh, p.shin)
    angles = kinematics.both_legs_angles(xp, kin)
    angles_prev = kinematics.both_legs_angles(
        xp, kinematics.leg_state(xp, lay.pivot_y, prev, p.thigh, p.shin)
    )
    limits_violated = kinematics.legs_outside_limits(xp, angles, p.hip_limits, p.knee_limits)

    traj = rewards.trajectory_terms(
        xp,
        p,
        steps=time,
        prev_heel=prev,
        heel=heel,
        collided=collided,
        clearance=clearance,
        reached_goal=reached,
        missed_mid=missed_mid,
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
    turn = (
        None
        if action is None or last_action is None
        else rewards.turn_of(xp, p.directions, action, last_action)
    )
    wearer = rewards.wearer_terms(
        xp, p, heel=heel, top=lay.height, angles_prev=angles_prev, angles=angles, turn=turn
    )
    done = terminated(xp, p, reached, collided)
    mid = xp.stack([mid_y, mid_z], axis=-1)
    goal = xp.stack([lay.goal_y, 0.0 * lay.goal_y], axis=-1)
    shaping = rewards.shaping_reward(
        xp,
        p,
        rewards.progress_potential(xp, prev, mid, goal, visited_mid),
        rewards.progress_potential(xp, heel, mid, goal, visited),
        done,
    )
    reward = rewards.total_reward(xp, p, traj, exo, wearer) + shaping
    info = {
        "traj_terms": traj,
        "exo_terms": exo,
        "wearer_terms": wearer,
        "shaping": shaping,
        "clearance": clearance,
        "collision": collided,
        "goal_reached": reached,
        "joint_limit_violation": limits_violated,
        "leg_length_violation": exo[..., 1] < 0,
        "joint_angles": angles,
        "heel": heel,
        "hip": kin.hip,
        # m the heel is behind its furthest y so far (eq 2.31's condition; the safe-swing rule's measure)
        "backward": run_max - heel[..., 0],
    }
    return {
        "visited_mid": visited,
        "reward": reward,
        "terminated": done,
        "info": info,
        "max_y": xp.maximum(run_max, heel[..., 0]),
    }
