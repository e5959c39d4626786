"""jaxexo.physics.kinematics: hip model (eq 2.3, 2.42), knee IK (eq 2.4-2.11), joint angles, limits, atan2."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from jaxexo.physics.kinematics import (
    ANGLE_EPS,
    MIN_HIP_HEIGHT_FRACTION,
    atan2,
    hip_position,
    joint_angles,
    joint_limit_violation,
    knee_position,
    leg_state,
)

T = S = 0.5
DEG = math.pi / 180.0


def hip(pivot_y, heel, t=T, s=S):
    return hip_position(np, pivot_y, np.asarray(heel, dtype=np.float64), t, s)


# --------------------------------------------------------------------------------------------
# Hip (eq 2.42 read as dist_y = (p_y - f_y) / 2)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "pivot_y, heel, expected",
    [
        (0.45, (0.0, 0.0), (0.225, math.sqrt(1.0 - 0.225**2))),
        (0.60, (0.0, 0.0), (0.30, math.sqrt(0.91))),
        (0.0, (0.0, 0.0), (0.0, 1.0)),  # heels together: straight up
        (0.0, (0.70, 0.0), (0.35, math.sqrt(1.0 - 0.35**2))),  # swing heel ahead of the pivot
        (
            0.45,
            (0.0, 0.30),
            (0.225, math.sqrt(1.0 - 0.225**2)),
        ),  # a raised heel does not move the hip
        (0.0, (2.5, 0.0), (1.25, MIN_HIP_HEIGHT_FRACTION * 1.0)),  # > 2 legs apart: clamped height
    ],
)
def test_hip_position(pivot_y, heel, expected):
    np.testing.assert_allclose(hip(pivot_y, heel), expected, atol=1e-12)


def test_hip_position_other_leg_lengths():
    # t = 0.4, s = 0.45: leg 0.85; heels 0.5 apart -> dist_y 0.25.
    np.testing.assert_allclose(
        hip(0.5, (0.0, 0.0), 0.4, 0.45), (0.25, math.sqrt(0.85**2 - 0.25**2)), atol=1e-12
    )


@given(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0), st.floats(0.0, 0.5))
def test_stance_leg_is_straight(pivot_y, heel_y, heel_z):
    # The hip sits above the heels' midpoint at the height of a straight stance leg (eq 2.3), unless
    # the heels are (nearly) two legs apart, where the height is clamped.
    h = hip(pivot_y, (heel_y, heel_z))
    assert h[1] >= MIN_HIP_HEIGHT_FRACTION * (T + S) - 1e-12
    assume((0.5 * (pivot_y - heel_y)) ** 2 <= (T + S) ** 2 * (1 - MIN_HIP_HEIGHT_FRACTION**2))
    assert h[0] == pytest.approx(0.5 * (pivot_y + heel_y), abs=1e-12)
    assert math.hypot(h[0] - pivot_y, h[1]) == pytest.approx(T + S, abs=1e-9)


def test_hip_position_vectorised():
    heels = np.array([[0.0, 0.0], [0.7, 0.0], [0.35, 0.2]])
    h = hip_position(np, 0.35, heels, T, S)
    assert h.shape == (3, 2)
    np.testing.assert_allclose(h[:, 0], [0.175, 0.525, 0.35])
    np.testing.assert_allclose(h[:, 1], [math.sqrt(1 - 0.175**2)] * 2 + [1.0])


# --------------------------------------------------------------------------------------------
# Knee (eq 2.4-2.11, forward-bending solution as a pair)
# --------------------------------------------------------------------------------------------


def test_knee_right_angle_forward():
    # Foot straight below the hip at sqrt(2) * 0.5: a 90-degree knee, ahead of the hip-foot line.
    h = np.array([0.0, 1.0])
    f = np.array([0.0, 1.0 - math.sqrt(2.0) * 0.5])
    k, r = knee_position(np, h, f, T, S)
    assert r == pytest.approx(math.sqrt(2.0) * 0.5)
    np.testing.assert_allclose(k, [0.5 / math.sqrt(2.0), 1.0 - 0.5 / math.sqrt(2.0)], atol=1e-12)
    hip_a, knee_a = joint_angles(np, h, k, f)
    assert hip_a == pytest.approx(45 * DEG, abs=1e-6)
    assert knee_a == pytest.approx(-90 * DEG, abs=1e-6)


def test_knee_straight_leg():
    h = np.array([0.2, 1.0])
    f = np.array([0.2, 0.0])
    k, r = knee_position(np, h, f, T, S)
    assert r == pytest.approx(1.0)
    np.testing.assert_allclose(k, [0.2, 0.5], atol=1e-7)
    hip_a, knee_a = joint_angles(np, h, k, f)
    assert hip_a == pytest.approx(0.0, abs=1e-6) and knee_a == pytest.approx(0.0, abs=1e-3)


def test_knee_unreachable_points_at_foot():
    # |hip - foot| = 1.5 > t + s: the straight leg points at the foot (eq 2.6 clamp).
    h = np.array([0.0, 1.0])
    f = np.array([0.9, -0.2])
    k, r = knee_position(np, h, f, T, S)
    assert r == pytest.approx(1.5)
    np.testing.assert_allclose(k, h + 0.5 * (f - h) / 1.5, atol=1e-12)


def test_knee_foot_forward_and_high():
    # Foot ahead and up: knee still on the forward side of the hip-foot line (larger y).
    h = np.array([0.0, 1.0])
    f = np.array([0.3, 0.5])
    k, _ = knee_position(np, h, f, T, S)
    assert np.linalg.norm(k - h) == pytest.approx(T)
    assert np.linalg.norm(k - f) == pytest.approx(S)
    # The other intersection is the reflection across the hip-foot line.
    u = (f - h) / np.linalg.norm(f - h)
    proj = h + np.dot(k - h, u) * u
    other = 2 * proj - k
    assert k[0] > other[0]


def test_knee_other_segment_lengths():
    t, s = 0.45, 0.4
    h = np.array([0.1, 0.9])
    f = np.array([0.0, 0.2])
    k, r = knee_position(np, h, f, t, s)
    assert np.linalg.norm(k - h) == pytest.approx(t)
    assert np.linalg.norm(k - f) == pytest.approx(s)


# --------------------------------------------------------------------------------------------
# Joint angles: hip + in flexion (knee ahead of hip), knee 0 straight and - in flexion
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("angle_deg", [-25.0, 0.0, 30.0, 100.0])
def test_straight_leg_hip_angle(angle_deg):
    a = angle_deg * DEG
    h = np.array([0.0, 1.0])
    k = h + T * np.array([math.sin(a), -math.cos(a)])
    f = h + (T + S) * np.array([math.sin(a), -math.cos(a)])
    hip_a, knee_a = joint_angles(np, h, k, f)
    assert hip_a == pytest.approx(a, abs=1e-6)
    assert knee_a == pytest.approx(0.0, abs=1e-6)


def test_flexed_knee_negative_and_beyond_90_degrees():
    # Thigh 120 deg forward (beyond +-90: atan2), shank hanging straight down: knee -120 deg.
    h = np.array([0.0, 1.0])
    k = h + T * np.array([math.sin(120 * DEG), -math.cos(120 * DEG)])
    f = k + np.array([0.0, -S])
    hip_a, knee_a = joint_angles(np, h, k, f)
    assert hip_a == pytest.approx(120 * DEG, abs=1e-6)
    assert knee_a == pytest.approx(-120 * DEG, abs=1e-6)


def test_leg_state_signs_and_lengths():
    # Pivot at the obstacle centre 0.45, swing heel at the start 0: both legs straight,
    # the stance foot ahead of the hip (flexion +), the swing foot behind (extension -).
    ks = leg_state(np, 0.45, np.array([0.0, 0.0]), T, S)
    expected_hip = np.asarray([0.225, math.sqrt(1 - 0.225**2)])
    np.testing.assert_allclose(ks.hip, expected_hip, atol=1e-12)
    a = math.asin(0.225)
    assert ks.hip_stance == pytest.approx(a, abs=1e-6)
    assert ks.hip_swing == pytest.approx(-a, abs=1e-6)
    assert abs(ks.knee_stance_angle) < ANGLE_EPS
    assert abs(ks.knee_swing_angle) < ANGLE_EPS
    assert ks.leg_swing == pytest.approx(1.0) and ks.leg_stance == pytest.approx(1.0)
    np.testing.assert_allclose(ks.knee_stance, 0.5 * (expected_hip + [0.45, 0.0]), atol=1e-6)
    # Raise the swing heel under the hip: the swing knee flexes (negative), forward of the hip.
    ks = leg_state(np, 0.45, np.array([0.225, 0.4]), T, S)
    assert ks.knee_swing_angle < -10 * DEG
    assert ks.hip_swing > 10 * DEG
    assert ks.knee_swing[0] > 0.225
    assert set(ks._fields) == {
        "hip",
        "knee_swing",
        "knee_stance",
        "leg_swing",
        "leg_stance",
        "hip_swing",
        "knee_swing_angle",
        "hip_stance",
        "knee_stance_angle",
    }


# --------------------------------------------------------------------------------------------
# Joint limits (eq 2.50)
# --------------------------------------------------------------------------------------------

LIMITS = (-30 * DEG, 115 * DEG, -100 * DEG, 0.0)


@pytest.mark.parametrize(
    "hip_a, knee_a, violated",
    [
        (0.0, 0.0, False),  # straight leg, exactly at the knee's 0 limit
        (0.0, 0.5 * ANGLE_EPS, False),  # float rounding within the tolerance
        (0.0, 0.01, True),  # knee hyperextension
        (-29 * DEG, -50 * DEG, False),
        (-31 * DEG, -50 * DEG, True),  # hip extension beyond -30
        (114 * DEG, -99 * DEG, False),
        (116 * DEG, -50 * DEG, True),  # hip flexion beyond 115
        (30 * DEG, -101 * DEG, True),  # knee flexion beyond 100
    ],
)
def test_joint_limit_violation(hip_a, knee_a, violated):
    assert bool(joint_limit_violation(np, hip_a, knee_a, *LIMITS)) is violated


def test_joint_limit_violation_vectorised():
    h = np.array([0.0, -1.0, 0.5, 2.1])
    q = np.array([0.0, -0.5, -1.8, -0.5])
    np.testing.assert_array_equal(
        joint_limit_violation(np, h, q, *LIMITS), [False, True, True, True]
    )


# --------------------------------------------------------------------------------------------
# Fast atan2
# --------------------------------------------------------------------------------------------


def test_atan2_all_quadrants_and_axes():
    ang = np.linspace(-math.pi, math.pi, 3601)[1:]  # (-pi, pi]
    for rad in (1e-3, 0.5, 1.0, 37.0):
        y, x = rad * np.sin(ang), rad * np.cos(ang)
        np.testing.assert_allclose(atan2(np, y, x), np.arctan2(y, x), atol=1e-6, rtol=0)
    axes = np.array(
        [
            [0.0, 1.0],
            [1.0, 0.0],
            [0.0, -1.0],
            [-1.0, 0.0],
            [0.0, 0.0],
            [1.0, 1.0],
            [1.0, -1.0],
            [-1.0, 1.0],
            [-1.0, -1.0],
            [2.0, -3.0],
        ]
    )
    y, x = axes[:, 0], axes[:, 1]
    np.testing.assert_allclose(atan2(np, y, x), np.arctan2(y, x), atol=1e-6, rtol=0)
    assert float(atan2(np, np.array(0.0), np.array(-1.0))) == pytest.approx(math.pi)
    assert float(atan2(np, np.array(-1e-9), np.array(-1.0))) == pytest.approx(-math.pi, abs=1e-6)


@given(st.floats(-10, 10, allow_subnormal=False), st.floats(-10, 10, allow_subnormal=False))
def test_atan2_random(y, x):
    # Signed zeros are normalised (atan2(0, -0.0) is pi in IEEE, 0 here: the same degenerate point).
    y, x = y + 0.0, x + 0.0
    assert float(atan2(np, np.asarray(y), np.asarray(x))) == pytest.approx(
        math.atan2(y, x), abs=1e-6
    )


def test_atan2_jax_float32():
    jnp = pytest.importorskip("jax.numpy")
    rng = np.random.default_rng(0)
    y = rng.uniform(-2, 2, 4096).astype(np.float32)
    x = rng.uniform(-2, 2, 4096).astype(np.float32)
    got = np.asarray(atan2(jnp, jnp.asarray(y), jnp.asarray(x)))
    assert got.dtype == np.float32
    np.testing.assert_allclose(
        got, np.arctan2(y.astype(np.float64), x.astype(np.float64)), atol=1e-6, rtol=0
    )


# --------------------------------------------------------------------------------------------
# Property: IK closure for every reachable foot
# --------------------------------------------------------------------------------------------


@given(
    st.floats(0.2, 0.8),
    st.floats(0.2, 0.8),  # thigh, shin
    st.floats(-1.0, 1.0),
    st.floats(0.0, 1.5),  # hip
    st.floats(0.0, 1.0),
    st.floats(-math.pi, math.pi),  # reach fraction, direction
)
def test_ik_closure(t, s, hy, hz, frac, phi):
    lo, hi = max(abs(t - s), 1e-3) + 1e-3, t + s  # fully folded (r = |t - s|): angle +-pi
    r = lo + frac * (hi - lo)
    h = np.array([hy, hz])
    f = h + r * np.array([math.cos(phi), math.sin(phi)])
    k, rr = knee_position(np, h, f, t, s)
    assert rr == pytest.approx(r, abs=1e-12)
    assert np.linalg.norm(k - h) == pytest.approx(t, abs=1e-7)
    assert np.linalg.norm(k - f) == pytest.approx(s, abs=1e-7)
    # The knee is the flexing one of the two intersections (knee angle <= 0); with the foot below the
    # hip it is the forward (larger-y) one of eq 2.11: the other is its mirror across the hip-foot line.
    u = (f - h) / r
    proj = h + np.dot(k - h, u) * u
    other = 2 * proj - k
    assert joint_angles(np, h, k, f)[1] <= ANGLE_EPS
    if f[1] < h[1]:
        assert k[0] >= other[0] - 1e-9


@given(st.floats(-0.3, 1.3), st.floats(-0.3, 1.3), st.floats(0.0, 0.8))
def test_leg_state_closure(pivot_y, heel_y, heel_z):
    ks = leg_state(np, pivot_y, np.array([heel_y, heel_z]), T, S)
    heel = np.array([heel_y, heel_z])
    assert ks.leg_swing == pytest.approx(np.linalg.norm(ks.hip - heel))
    assume(ks.leg_swing <= T + S)
    assert np.linalg.norm(ks.knee_swing - ks.hip) == pytest.approx(T, abs=1e-6)
    assert np.linalg.norm(ks.knee_swing - heel) == pytest.approx(S, abs=1e-6)
    # Knee flexion is never positive (the knee bends, never hyperextends) within rounding.
    assert ks.knee_swing_angle <= ANGLE_EPS
    assert ks.knee_stance_angle <= ANGLE_EPS


def test_knee_bends_forward_with_heel_above_hip():
    # Reachable in the env (bounds_y up to 1.3 m, max_z 0.8 m): pivot at the start (0), heel 1.21 m
    # ahead at the ceiling. The hip is at (0.605, 0.796), just below the heel.
    ks = leg_state(np, 0.0, np.array([1.21, 0.80]), T, S)
    assert ks.hip[1] < 0.80
    # Same knee flexion magnitude either way (|hip - heel| fixes it): about 105.5 degrees.
    assert abs(ks.knee_swing_angle) == pytest.approx(105.54 * DEG, abs=0.01)
    assert ks.knee_swing_angle < 0, (
        f"knee angle {math.degrees(ks['knee_swing_angle']):.1f} deg (hyperextension)"
    )


# --------------------------------------------------------------------------------------------
# NumPy (float64) vs jax.numpy (float32)
# --------------------------------------------------------------------------------------------


def test_leg_state_numpy_vs_jax():
    jnp = pytest.importorskip("jax.numpy")
    ys = np.linspace(-0.2, 1.1, 27)
    zs = np.linspace(0.0, 0.6, 13)
    heels = np.stack(np.meshgrid(ys, zs, indexing="ij"), axis=-1).reshape(-1, 2)
    for pivot_y in (0.0, 0.225, 0.45):
        ks_np = leg_state(np, pivot_y, heels, T, S)
        ks_j = leg_state(jnp, jnp.float32(pivot_y), jnp.asarray(heels, jnp.float32), T, S)
        assert type(ks_np) is type(ks_j)
        # Away from a straight swing leg the float32 IK is accurate to ~1e-6.
        bent = ks_np.leg_swing < 0.95
        assert bent.sum() > 50
        for key in ("hip", "leg_swing", "leg_stance"):
            np.testing.assert_allclose(
                np.asarray(getattr(ks_j, key)), getattr(ks_np, key), atol=1e-5, err_msg=key
            )
        for key in ("knee_swing", "hip_swing", "knee_swing_angle"):
            np.testing.assert_allclose(
                np.asarray(getattr(ks_j, key))[bent],
                getattr(ks_np, key)[bent],
                atol=1e-4,
                err_msg=key,
            )
            # At a straight leg sqrt(t^2 - a^2) amplifies float32 rounding: a looser bound.
            np.testing.assert_allclose(
                np.asarray(getattr(ks_j, key)), getattr(ks_np, key), atol=3e-3, err_msg=key
            )
        # The stance leg is always straight: float32 rounding only.
        for key in ("knee_stance", "hip_stance", "knee_stance_angle"):
            np.testing.assert_allclose(
                np.asarray(getattr(ks_j, key)), getattr(ks_np, key), atol=3e-3, err_msg=key
            )
