"""The thesis's reward function (eq 2.1-2.2, 2.29-2.52) and the default model's additions (shaping,
the wearer's costs), written for the array module ``xp`` (numpy or jax.numpy). How the terms are
read where the thesis is ambiguous: docs/training.md#modelling-decisions; the fields:
docs/configuration.md#reward.
"""

from __future__ import annotations

import numpy as np

from jaxexo.physics.kinematics import LENGTH_EPS, leg_too_long  # noqa: F401 (LENGTH_EPS re-exported)

TRAJECTORY_TERMS = (
    "steps",  # r0, eq 2.29
    "collision",  # r1, eq 2.30
    "backward",  # r2, eq 2.31
    "goal",  # r3, eq 2.32
    "mid_goal",  # r4, eq 2.33
    "max_height",  # r5, eq 2.34
    "safety",  # r6, eq 2.35
    "z_monotone",  # r7, eq 2.36-2.37
)
EXO_TERMS = (
    "hip_lowering",  # e0, eq 2.43 (HLC)
    "leg_length",  # e1, eq 2.45
    "joint_limits",  # e2, eq 2.50
    "hip_height",  # e3, eq 2.51
)


def normalize_weights(weights) -> np.ndarray:
    """Eq 2.38 / 2.52 with eq 2.2: non-negative weights scaled to sum to 0.5."""
    w = np.asarray(weights, dtype=np.float64)
    return 0.5 * w / w.sum()


def trajectory_terms(
    xp, c, *, steps, prev_heel, heel, collided, clearance, reached_goal, missed_mid, mid_y, max_z
):
    """The eight trajectory terms (..., 8). ``c`` holds the constants (attributes, see EnvParams)."""
    n = c.step_threshold
    s = steps.astype(heel.dtype)
    zero = xp.zeros_like(heel[..., 0])
    r0 = xp.where(s <= n, s / n, -s / n)  # eq 2.29
    r1 = xp.where(collided, -c.collision_penalty, zero)  # eq 2.30
    r2 = xp.where(heel[..., 0] < prev_heel[..., 0], -c.backward_penalty, zero)  # eq 2.31
    r3 = xp.where(reached_goal, c.goal_reward, zero)  # eq 2.32
    r4 = xp.where(missed_mid, -c.mid_goal_penalty, zero)  # eq 2.33
    r5 = xp.where(heel[..., 1] > max_z, -c.max_height_penalty, zero)  # eq 2.34
    r6 = xp.where(clearance < c.safety_distance, -c.safety_penalty, zero)  # eq 2.35
    rising = heel[..., 1] >= prev_heel[..., 1]
    falling = heel[..., 1] <= prev_heel[..., 1]
    before_mid = prev_heel[..., 0] <= mid_y
    r7 = xp.where(
        xp.where(before_mid, rising, falling), zero, -c.z_monotone_penalty
    )  # eq 2.36-2.37
    return xp.stack([r0, r1, r2, r3, r4, r5, r6, r7], axis=-1)


def exo_terms(xp, c, *, hip_z, leg_swing, leg_stance, limits_violated):
    """The four exoskeleton terms (..., 4) (eq 2.43, 2.45, 2.50, 2.51)."""
    leg = c.thigh + c.shin
    zero = xp.zeros_like(hip_z)
    e0 = xp.where(hip_z / leg < c.hlc_threshold, -c.hlc_penalty * leg / hip_z, zero)  # eq 2.43
    too_long = leg_too_long(xp, leg_swing, leg_stance, c.thigh, c.shin, c.leg_length_tolerance)
    e1 = xp.where(too_long, -c.leg_length_penalty, zero)  # eq 2.45
    e2 = xp.where(limits_violated, -c.joint_limit_penalty, zero)  # eq 2.50
    e3 = xp.where(hip_z > c.max_hip_z, -c.hip_height_penalty, zero)  # eq 2.51
    return xp.stack([e0, e1, e2, e3], axis=-1)


# Costs a wearer feels (not in the thesis; added to eq 2.1's reward like the shaping term): under
# the shield no greedy move comes within the clearance, so the reward may pay for how it feels.
WEARER_TERMS = (
    "lift",  # m of heel height above the obstacle's top plus the shield's clearance
    "move_time",  # s the joint drives need for the move at their velocity limits
    "turn",  # 1 - cos of the angle between this move and the last (0: straight on; 2: reversed)
)


def wearer_terms(xp, c, *, heel, top, angles_prev, angles, turn=None):
    """The wearer's costs (..., 3), all <= 0: minus the heel's height above what the clearance needs
    over the obstacle's highest point (top + ``c.shield_clearance``; nothing below it); minus the
    move's time at the drives' velocity limits, max over the four joints of |dq| / v_max (the
    joint-space distance of the move over ``c.joint_speed`` = (hip, knee, hip, knee) rad/s), so that a
    sum over the swing approximates its timed duration at the device; and minus ``turn``, the move's
    change of direction (``turn_of``; None: 0). The drives must slow down at every corner of the path,
    and the smoothing spline cuts corners (and must then be corrected away from the obstacle): a
    path that turns gently is quicker at the device and keeps its shape when smoothed."""
    lift = xp.maximum(heel[..., 1] - (top + c.shield_clearance), 0.0)
    move_time = xp.max(xp.abs(angles - angles_prev) / c.joint_speed, axis=-1)
    turn = xp.zeros_like(lift) if turn is None else turn
    return xp.stack([-lift, -move_time, -turn], axis=-1)


def turn_of(xp, directions, action, last_action):
    """1 - cos of the angle between move ``action`` and the move before it, ``last_action`` (-1: none,
    no turn), both indices into ``directions`` (NUM_ACTIONS, 2) of unit vectors."""
    last = xp.asarray(last_action)
    cos = xp.sum(directions[action] * directions[xp.maximum(last, 0)], axis=-1)
    return xp.where(last >= 0, 1.0 - cos, 0.0)


def progress_potential(xp, heel, mid, goal, visited_mid):
    """Potential for optional shaping (not in the thesis): minus the path length still to go, through
    the mid-goal until it is visited, then straight to the goal (m). Shaping with
    F = gamma * Phi(s') - Phi(s) (Phi = 0 at termination) leaves the optimal policy unchanged
    (Ng, Harada & Russell 1999) and gives the sparse goal reward a direction."""

    def norm(v):
        return xp.sqrt(xp.sum(v * v, axis=-1))

    via_mid = norm(mid - heel) + norm(goal - mid)
    return -xp.where(visited_mid, norm(goal - heel), via_mid)


def shaping_reward(xp, c, phi_prev, phi_next, terminated):
    """Potential-based shaping term, ``c.progress_shaping`` per metre of progress (0 disables it).

    With ``c.shaping_discount`` equal to the learner's gamma the optimal policy is exactly unchanged,
    but then a step that does not move (pushing into the ground) earns (1 - gamma) * |Phi| > 0, a
    bonus for standing still that trapped training in practice. The default discount 1 pays
    progress exactly when it is made and nothing for standing still; it favours reaching the goal
    sooner, which the thesis wants anyway (r0, eq 2.29)."""
    gamma = c.shaping_discount
    return c.progress_shaping * (gamma * xp.where(terminated, 0.0, phi_next) - phi_prev)


def total_reward(xp, c, traj, exo, wearer=None):
    """Eq 2.1 / 2.39 / 2.52: alpha . T + beta . E with the normalised weights held in ``c``, plus the
    wearer's costs weighted by ``c.lift_cost`` (1/m), ``c.time_cost`` (1/s) and ``c.turn_cost`` (per
    unit of 1 - cos) (0, 0, 0: the thesis)."""
    r = xp.sum(traj * c.traj_weights, axis=-1) + xp.sum(exo * c.exo_weights, axis=-1)
    if wearer is not None:
        r = (
            r
            + c.lift_cost * wearer[..., 0]
            + c.time_cost * wearer[..., 1]
            + c.turn_cost * wearer[..., 2]
        )
    return r
