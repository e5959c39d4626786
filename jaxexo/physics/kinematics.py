"""Exoskeleton kinematics in the sagittal plane (hip eq 2.42, knee IK eq 2.4-2.11, joint angles eq
2.46-2.49), written once for the array module ``xp`` and shared by the JAX environment and the NumPy
generator. Positions are (..., 2) arrays of (y, z) in metres, angles radians. The hip model, the
knee's branch and the angle signs: docs/training.md#modelling-decisions.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

# Below this fraction of the leg length the hip height is clamped (heels over two legs apart).
MIN_HIP_HEIGHT_FRACTION = 0.05


_TAN_PI_8 = math.tan(math.pi / 8.0)


def atan2(xp, y, x):
    """atan2 from multiply-adds and one division (Cephes atanf range reduction and polynomial).

    Accurate to float32 rounding (a few 1e-7 rad), and unlike the library atan2 it vectorises in
    XLA's CPU code: joint angles are computed every environment step. NumPy's own arctan2 is one
    call and the same function to that rounding, so NumPy callers get it."""
    if xp is np:
        return np.arctan2(y, x)
    ax = xp.abs(x)
    ay = xp.abs(y)
    hi = xp.maximum(ax, ay)
    lo = xp.minimum(ax, ay)
    a = lo / xp.where(hi > 0.0, hi, 1.0)  # in [0, 1]
    big = a > _TAN_PI_8
    t = xp.where(big, (a - 1.0) / (a + 1.0), a)  # in [-tan(pi/8), tan(pi/8)]
    z = t * t
    r = (
        ((8.05374449538e-2 * z - 1.38776856032e-1) * z + 1.99777106478e-1) * z - 3.33329491539e-1
    ) * z * t + t
    r = xp.where(big, r + math.pi / 4.0, r)
    r = xp.where(ay > ax, math.pi / 2.0 - r, r)
    r = xp.where(x < 0.0, math.pi - r, r)
    return xp.where(y < 0.0, -r, r)


def hip_position(xp, pivot_y, heel, thigh, shin):
    """Hip (..., 2) from the pivot heel's y (on the ground) and the swing heel (eq 2.3, 2.42)."""
    leg = thigh + shin
    dist_y = 0.5 * (pivot_y - heel[..., 0])
    hz2 = leg * leg - dist_y * dist_y
    hz = xp.sqrt(xp.maximum(hz2, (MIN_HIP_HEIGHT_FRACTION * leg) ** 2))
    return xp.concatenate([(0.5 * (pivot_y + heel[..., 0]))[..., None], hz[..., None]], axis=-1)


def knee_position(xp, hip, foot, thigh, shin):
    """Forward-bending knee (..., 2) for a hip and a heel (eq 2.4-2.11), and |hip - heel| (eq 2.4, 2.44)."""
    d = foot - hip
    r = xp.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])  # not xp.sum over 2: slow in NumPy
    r_safe = xp.maximum(r, 1e-12)
    u = d / r_safe[..., None]
    # Distance along hip->heel to the chord through both circle intersections (law of cosines,
    # eq 2.5); clamped to the reachable range like eq 2.6.
    a = xp.minimum(
        xp.maximum((thigh * thigh - shin * shin + r * r) / (2.0 * r_safe), -thigh), thigh
    )  # clip
    h = xp.sqrt(xp.maximum(thigh * thigh - a * a, 0.0))
    # Eq 2.11 as a pair: the knee on the +90 degree side of hip->heel flexes (knee angle <= 0); the
    # larger-y knee only while the heel is below the hip (docs/training.md#modelling-decisions).
    perp = xp.concatenate(
        [-u[..., 1:2], u[..., 0:1]], axis=-1
    )  # concatenate: cheaper than stack in NumPy
    knee = hip + a[..., None] * u + h[..., None] * perp
    return knee, r


def joint_angles(xp, hip, knee, foot):
    """Hip and knee angles (radians) of one leg (eq 2.49 with atan2): hip flexion +, knee flexion -."""
    thigh_angle = atan2(xp, knee[..., 0] - hip[..., 0], hip[..., 1] - knee[..., 1])
    shank_angle = atan2(xp, foot[..., 0] - knee[..., 0], knee[..., 1] - foot[..., 1])
    # Wrapped to [-pi, pi): both absolute angles lie in [-pi, pi], so their difference may not.
    knee_angle = xp.mod(shank_angle - thigh_angle + math.pi, 2.0 * math.pi) - math.pi
    return thigh_angle, knee_angle


class LegState(NamedTuple):
    """Both legs' kinematic state for a swing heel and a pivot heel on the ground (a NamedTuple, so
    a pytree for JAX without importing it; any leading shape ``...``)."""

    hip: Any  # (..., 2) m, eq 2.42
    knee_swing: Any  # (..., 2) m
    knee_stance: Any  # (..., 2) m
    leg_swing: Any  # (...,) m, |hip - heel| (eq 2.44)
    leg_stance: Any  # (...,) m
    hip_swing: Any  # (...,) rad
    knee_swing_angle: Any  # (...,) rad
    hip_stance: Any  # (...,) rad
    knee_stance_angle: Any  # (...,) rad


def leg_state(xp, pivot_y, heel, thigh, shin) -> LegState:
    """The full kinematic state of both legs, the swing heel at ``heel`` (..., 2)."""
    hip = hip_position(xp, pivot_y, heel, thigh, shin)
    pivot = xp.stack([pivot_y + 0.0 * heel[..., 0], 0.0 * heel[..., 1]], axis=-1)
    k_sw, m_sw = knee_position(xp, hip, heel, thigh, shin)
    k_st, m_st = knee_position(xp, hip, pivot, thigh, shin)
    h_sw, q_sw = joint_angles(xp, hip, k_sw, heel)
    h_st, q_st = joint_angles(xp, hip, k_st, pivot)
    return LegState(
        hip=hip,
        knee_swing=k_sw,
        knee_stance=k_st,
        leg_swing=m_sw,
        leg_stance=m_st,
        hip_swing=h_sw,
        knee_swing_angle=q_sw,
        hip_stance=h_st,
        knee_stance_angle=q_st,
    )


# Tolerance on joint limits: a straight leg is exactly at the knee's 0 limit, and float32 rounding
# must not turn it into a violation.
ANGLE_EPS = 1e-4


# The thesis pivot conditions (3.1), in the order pivot_position indexes them: (b)/(2), (a)/(1), (c)/(3).
PIVOT_CONDITIONS = ("agent", "obstacle", "between")


def pivot_position(xp, pivot_kind, start_y, center_y):
    """The three thesis pivot conditions (3.1), indexed like PIVOT_CONDITIONS: the pivot
    heel aligned with the swing heel's start, with the obstacle centre, or half-way between (m)."""
    return xp.where(
        pivot_kind == 0, start_y, xp.where(pivot_kind == 1, center_y, 0.5 * (start_y + center_y))
    )


def swing_heel_unreachable(xp, pivot_y, heel, thigh, shin, hip_limits, knee_limits):
    """Whether the swing leg cannot put its heel at ``heel`` (..., 2) with the pivot foot at
    ``pivot_y``: out of reach (longer than thigh + shin, eq 2.45) or outside its joint limits (eq 2.50).
    The feasibility rule of the config's obstacles and of the terrain families."""
    ks = leg_state(xp, pivot_y, heel, thigh, shin)
    return (ks.leg_swing > thigh + shin + 1e-9) | joint_limit_violation(
        xp, ks.hip_swing, ks.knee_swing_angle, *hip_limits, *knee_limits
    )


def joint_limit_violation(xp, hip_angle, knee_angle, hip_min, hip_max, knee_min, knee_max):
    """Eq 2.50's condition for one leg: any angle outside its limits."""
    return (
        (hip_angle > hip_max + ANGLE_EPS)
        | (hip_angle < hip_min - ANGLE_EPS)
        | (knee_angle > knee_max + ANGLE_EPS)
        | (knee_angle < knee_min - ANGLE_EPS)
    )


def both_legs_angles(xp, state):
    """(..., 4) [hip_swing, knee_swing, hip_stance, knee_stance] (rad) of a ``leg_state``: the layout
    ``legs_outside_limits`` and the environment's info["joint_angles"] use."""
    return xp.stack(
        [
            state.hip_swing,
            state.knee_swing_angle,
            state.hip_stance,
            state.knee_stance_angle,
        ],
        axis=-1,
    )


def legs_outside_limits(xp, angles, hip_limits, knee_limits):
    """Eq 2.50's condition for both legs: ``angles`` (..., 4) as [hip_swing, knee_swing, hip_stance,
    knee_stance] (rad); True where either leg has an angle outside its limits."""
    lim = lambda h, q: joint_limit_violation(  # noqa: E731
        xp, h, q, hip_limits[0], hip_limits[1], knee_limits[0], knee_limits[1]
    )
    return lim(angles[..., 0], angles[..., 1]) | lim(angles[..., 2], angles[..., 3])


# A straight leg's |hip - heel| rounds to t + s plus an ulp: not a violation of eq 2.45 (m).
LENGTH_EPS = 1e-5


def leg_too_long(xp, leg_swing, leg_stance, thigh, shin, tolerance):
    """Eq 2.45's condition: either leg's hip-heel distance exceeds thigh + shin by more than tolerance."""
    return xp.maximum(leg_swing, leg_stance) - (thigh + shin) > tolerance + LENGTH_EPS
