"""jaxexo.physics.rewards: the 8 trajectory terms (eq 2.29-2.37), the 4 exoskeleton terms (eq 2.43-2.51),
the weight normalisation (eq 2.2, 2.38, 2.52) and the total (eq 2.1); by hand and through the env."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from jaxexo.physics.rewards import (
    EXO_TERMS,
    TRAJECTORY_TERMS,
    exo_terms,
    normalize_weights,
    total_reward,
    trajectory_terms,
)

C = SimpleNamespace(
    step_threshold=30.0,
    collision_penalty=10.0,
    backward_penalty=1.5,
    goal_reward=20.0,
    mid_goal_penalty=3.0,
    max_height_penalty=4.0,
    safety_penalty=2.0,
    safety_distance=0.03,
    z_monotone_penalty=0.5,
    thigh=0.5,
    shin=0.5,
    hlc_penalty=1.25,
    hlc_threshold=0.9,
    leg_length_penalty=6.0,
    leg_length_tolerance=0.01,
    joint_limit_penalty=7.0,
    hip_height_penalty=8.0,
    max_hip_z=0.98,
    traj_weights=normalize_weights([1, 2, 3, 4, 5, 6, 7, 8]),
    exo_weights=normalize_weights([1, 1, 2, 4]),
)

# A neutral step: 10 steps, forward and level before the mid-goal, far from the obstacle,
# not at the goal, not past the mid-goal, low. Every penalty is 0, r0 = 10/30.
NEUTRAL = dict(
    steps=np.asarray(10),
    prev_heel=np.array([0.10, 0.05]),
    heel=np.array([0.13, 0.05]),
    collided=np.asarray(False),
    clearance=np.asarray(0.2),
    reached_goal=np.asarray(False),
    missed_mid=np.asarray(False),
    mid_y=np.asarray(0.45),
    max_z=np.asarray(0.30),
)


def traj(**changes):
    kw = {**NEUTRAL, **{k: np.asarray(v) for k, v in changes.items()}}
    out = trajectory_terms(np, C, **kw)
    assert out.shape == (8,)
    return out


def only(vec, index, value, names):
    """vec is zero except at index, where it equals value."""
    expected = np.zeros(len(names))
    expected[index] = value
    np.testing.assert_allclose(vec, expected, atol=1e-12, err_msg=f"term {names[index]}")


def test_term_names():
    assert TRAJECTORY_TERMS == (
        "steps",
        "collision",
        "backward",
        "goal",
        "mid_goal",
        "max_height",
        "safety",
        "z_monotone",
    )
    assert EXO_TERMS == ("hip_lowering", "leg_length", "joint_limits", "hip_height")


def test_neutral_step_has_only_the_step_term():
    only(traj(), 0, 10 / 30, TRAJECTORY_TERMS)


# r0, eq 2.29 -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "steps, expected", [(1, 1 / 30), (29, 29 / 30), (30, 1.0), (31, -31 / 30), (60, -2.0)]
)
def test_r0_steps(steps, expected):
    assert traj(steps=steps)[0] == pytest.approx(expected)


# r1, eq 2.30 -------------------------------------------------------------------------------
def test_r1_collision():
    t = traj(collided=True, clearance=0.2)  # clearance kept large so that r6 stays 0
    only(t[1:], 0, -10.0, TRAJECTORY_TERMS[1:])
    assert traj(collided=False)[1] == 0.0


# r2, eq 2.31 -------------------------------------------------------------------------------
def test_r2_backward():
    assert traj(heel=[0.07, 0.05])[2] == -1.5  # y decreased
    assert traj(heel=[0.10, 0.08])[2] == 0.0  # y unchanged (straight up)
    assert traj(heel=[0.13, 0.05])[2] == 0.0  # forward


# r3, eq 2.32 -------------------------------------------------------------------------------
def test_r3_goal():
    assert traj(reached_goal=True)[3] == 20.0
    assert traj(reached_goal=False)[3] == 0.0


# r4, eq 2.33 -------------------------------------------------------------------------------
def test_r4_mid_goal():
    assert traj(missed_mid=True)[4] == -3.0
    assert traj(missed_mid=False)[4] == 0.0


# r5, eq 2.34 -------------------------------------------------------------------------------
def test_r5_max_height():
    t = traj(prev_heel=[0.30, 0.30], heel=[0.30, 0.33])  # straight up, before the mid-goal
    only(t[1:], 4, -4.0, TRAJECTORY_TERMS[1:])
    assert traj(prev_heel=[0.30, 0.27], heel=[0.30, 0.30])[5] == 0.0  # exactly at max_z: allowed


# r6, eq 2.35 -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "clearance, expected", [(0.029, -2.0), (0.0, -2.0), (-0.05, -2.0), (0.03, 0.0), (0.5, 0.0)]
)
def test_r6_safety(clearance, expected):
    assert traj(clearance=clearance)[6] == expected


# r7, eq 2.36-2.37 --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "prev, heel, expected",
    [
        ((0.40, 0.10), (0.43, 0.07), -0.5),  # before the mid-goal (0.40 <= 0.45) and falling
        ((0.40, 0.10), (0.43, 0.13), 0.0),  # before and rising
        ((0.40, 0.10), (0.43, 0.10), 0.0),  # before and level
        ((0.45, 0.10), (0.48, 0.07), -0.5),  # exactly at the mid-goal y counts as before
        ((0.46, 0.10), (0.49, 0.13), -0.5),  # after and rising
        ((0.46, 0.10), (0.49, 0.07), 0.0),  # after and falling
        ((0.46, 0.10), (0.49, 0.10), 0.0),  # after and level
    ],
)
def test_r7_z_monotone(prev, heel, expected):
    assert traj(prev_heel=prev, heel=heel)[7] == expected


def test_trajectory_terms_vectorised():
    n = 4
    out = trajectory_terms(
        np,
        C,
        steps=np.array([1, 10, 30, 40]),
        prev_heel=np.tile([0.1, 0.05], (n, 1)),
        heel=np.array([[0.13, 0.05], [0.07, 0.05], [0.13, 0.5], [0.13, 0.05]]),
        collided=np.array([False, True, False, False]),
        clearance=np.array([0.2, 0.0, 0.2, 0.01]),
        reached_goal=np.array([False, False, False, True]),
        missed_mid=np.array([True, False, False, False]),
        mid_y=np.full(n, 0.45),
        max_z=np.full(n, 0.3),
    )
    assert out.shape == (n, 8)
    np.testing.assert_allclose(out[:, 0], [1 / 30, 10 / 30, 1.0, -40 / 30])
    np.testing.assert_allclose(out[:, 1], [0, -10, 0, 0])
    np.testing.assert_allclose(out[:, 2], [0, -1.5, 0, 0])
    np.testing.assert_allclose(out[:, 3], [0, 0, 0, 20])
    np.testing.assert_allclose(out[:, 4], [-3, 0, 0, 0])
    np.testing.assert_allclose(out[:, 5], [0, 0, -4, 0])
    np.testing.assert_allclose(out[:, 6], [0, -2, 0, -2])
    np.testing.assert_allclose(out[:, 7], [0, 0, 0, 0])


# Exoskeleton terms -----------------------------------------------------------------------------

NEUTRAL_EXO = dict(
    hip_z=np.asarray(0.97),
    leg_swing=np.asarray(0.8),
    leg_stance=np.asarray(1.0),
    limits_violated=np.asarray(False),
)


def exo(**changes):
    out = exo_terms(np, C, **{**NEUTRAL_EXO, **{k: np.asarray(v) for k, v in changes.items()}})
    assert out.shape == (4,)
    return out


def test_neutral_exo_is_zero():
    np.testing.assert_array_equal(exo(), np.zeros(4))


# e0, eq 2.43 -------------------------------------------------------------------------------
def test_e0_hip_lowering():
    # hip_z / (t + s) = 0.8 < 0.9: -o (t + s) / h_z = -1.25 / 0.8.
    only(exo(hip_z=0.8), 0, -1.25 / 0.8, EXO_TERMS)
    assert exo(hip_z=0.9)[0] == 0.0  # at the threshold: not lowered
    assert exo(hip_z=0.95)[0] == 0.0


# e1, eq 2.45 -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "swing, stance, expected",
    [
        (1.02, 1.0, -6.0),  # swing leg 2 cm too long (> tolerance 1 cm)
        (0.8, 1.02, -6.0),  # stance leg too long
        (1.005, 1.0, 0.0),  # within the tolerance
        (0.5, 0.5, 0.0),
    ],
)
def test_e1_leg_length(swing, stance, expected):
    assert exo(leg_swing=swing, leg_stance=stance)[1] == expected


# e2, eq 2.50 -------------------------------------------------------------------------------
def test_e2_joint_limits():
    only(exo(limits_violated=True), 2, -7.0, EXO_TERMS)
    assert exo(limits_violated=False)[2] == 0.0


# e3, eq 2.51 -------------------------------------------------------------------------------
def test_e3_hip_height():
    only(exo(hip_z=0.99), 3, -8.0, EXO_TERMS)
    assert exo(hip_z=0.98)[3] == 0.0


def test_e1_not_fired_by_rounding_within_two_legs():
    from jaxexo.config import RewardConfig
    from jaxexo.physics.kinematics import leg_state

    c = SimpleNamespace(**{**vars(C), "leg_length_tolerance": RewardConfig().leg_length_tolerance})
    # Hand case (float64): pivot heel at y = 0.06, swing heel on the ground at 1.172: 1.112 m apart,
    # the hip is placed so that both legs are exactly t + s = 1 long.
    ks = leg_state(np, 0.06, np.array([1.172, 0.0]), 0.5, 0.5)
    e = exo_terms(
        np,
        c,
        hip_z=ks.hip[1],
        leg_swing=ks.leg_swing,
        leg_stance=ks.leg_stance,
        limits_violated=np.asarray(False),
    )
    assert e[1] == 0.0, f"leg_stance = {ks['leg_stance']!r}"
    # A grid of grounded heels against pivots in the sampled range, float64 and float32.
    import jax.numpy as jnp

    P, H = np.meshgrid(np.linspace(0.0, 0.5, 51), np.linspace(-0.27, 1.3, 786), indexing="ij")
    heel = np.stack([H, 0 * H], -1)
    for xp, dt in ((np, np.float64), (jnp, jnp.float32)):
        ks = leg_state(xp, xp.asarray(P, dt), xp.asarray(heel, dt), 0.5, 0.5)
        e = exo_terms(
            xp,
            c,
            hip_z=ks.hip[..., 1],
            leg_swing=ks.leg_swing,
            leg_stance=ks.leg_stance,
            limits_violated=xp.zeros(P.shape, bool),
        )
        assert int((np.asarray(e[..., 1]) != 0).sum()) == 0, xp.__name__


# Weights and total ----------------------------------------------------------------------------


@given(st.lists(st.floats(0.0, 100.0), min_size=1, max_size=12).filter(lambda w: sum(w) > 1e-6))
def test_normalize_weights_sums_to_half(w):
    n = normalize_weights(w)
    assert n.sum() == pytest.approx(0.5)
    assert np.all(n >= 0)
    # Proportional to the input (eq 2.38 up to the 0.5 of eq 2.2).
    np.testing.assert_allclose(n * sum(w), 0.5 * np.asarray(w), rtol=1e-9, atol=1e-12)


def test_normalize_weights_values():
    np.testing.assert_allclose(normalize_weights([1, 1, 1, 1]), [0.125] * 4)
    np.testing.assert_allclose(normalize_weights([3, 0, 1]), [0.375, 0.0, 0.125])


def test_total_reward():
    t = np.arange(1.0, 9.0)  # 1 .. 8
    e = np.array([-1.0, -2.0, -3.0, -4.0])
    expected = float(np.dot(C.traj_weights, t) + np.dot(C.exo_weights, e))
    assert total_reward(np, C, t, e) == pytest.approx(expected)
    # By hand: alpha = 0.5 * (1..8) / 36, beta = 0.5 * (1, 1, 2, 4) / 8.
    by_hand = 0.5 * sum(i * i for i in range(1, 9)) / 36 + 0.5 * (-1 - 2 - 6 - 16) / 8
    assert total_reward(np, C, t, e) == pytest.approx(by_hand)
    # Batched.
    out = total_reward(np, C, np.stack([t, 0 * t]), np.stack([e, 0 * e]))
    np.testing.assert_allclose(out, [by_hand, 0.0])


# --------------------------------------------------------------------------------------------
# Through the environment: a hand-made state, one chosen action, one term fires
# --------------------------------------------------------------------------------------------

RIGHT, UP, LEFT, DOWN = 0, 9, 18, 27


@pytest.fixture(scope="module")
def env_tools(mixed_env, mixed_step):
    import jax
    import jax.numpy as jnp

    from jaxexo.physics.geometry import Obstacle

    # The mixed config pins the thesis-default reward and mid-goal constants (conftest.MIXED_RAW);
    # its outline size (16) fits every named obstacle.
    env, params = mixed_env, mixed_env.default_params

    def run(
        heel, action, *, obstacle=None, pivot="obstacle", time=0, visited=False, p=None, last=-1
    ):
        lay = env.layout_for(obstacle or Obstacle.named("base1"), pivot=pivot)
        _, state = env.init_state(lay, params)
        state = state.replace(
            heel=jnp.asarray(heel, jnp.float32),
            time=jnp.asarray(time, jnp.int32),
            visited_mid=jnp.asarray(visited),
            last_action=jnp.asarray(last, jnp.int32),
        )
        obs, new_state, reward, terminated, truncated, info = mixed_step(
            jax.random.PRNGKey(0), state, action, params if p is None else p
        )
        return dict(
            obs=obs,
            state=new_state,
            reward=float(reward),
            terminated=bool(terminated),
            traj=np.asarray(info["traj_terms"]),
            exo=np.asarray(info["exo_terms"]),
            info=info,
        )

    return SimpleNamespace(run=run, env=env, params=params)


def test_env_neutral_step(env_tools):
    # Base 1 spans y in [0.35, 0.55], 0.10 high; pivot at its centre. From the start, move forward.
    out = env_tools.run([0.0, 0.0], RIGHT)
    np.testing.assert_allclose(out["traj"], [1 / 30, 0, 0, 0, 0, 0, 0, 0], atol=1e-6)
    np.testing.assert_array_equal(out["exo"], np.zeros(4))
    assert not out["terminated"]
    p = env_tools.params
    expected = float(
        np.dot(np.asarray(p.traj_weights), out["traj"])
        + np.dot(np.asarray(p.exo_weights), out["exo"])
    )
    # Optional shaping (not a thesis term, reported separately when the package adds it).
    expected += float(out["info"].get("shaping", 0.0))
    assert out["reward"] == pytest.approx(expected, abs=1e-6)
    np.testing.assert_allclose(np.asarray(out["state"].heel), [0.03, 0.0], atol=1e-6)


def test_env_steps_term_beyond_threshold(env_tools):
    out = env_tools.run([0.0, 0.0], RIGHT, time=40)
    assert out["traj"][0] == pytest.approx(-41 / 30, rel=1e-6)


def test_env_collision(env_tools):
    # Toe at 0.33 + 0.20 = 0.53 at z = 0.05: the foot enters Base 1 through its near side.
    out = env_tools.run([0.30, 0.05], RIGHT)
    assert out["traj"][1] == -10.0
    assert out["traj"][6] == -2.0  # clearance 0 < safety distance too
    assert bool(out["info"]["collision"]) and not out["terminated"]  # penalty mode: continue
    assert float(out["info"]["clearance"]) <= 0.0


def test_env_backward(env_tools):
    out = env_tools.run([0.10, 0.0], LEFT)
    assert out["traj"][2] == -1.0
    assert env_tools.run([0.10, 0.0], UP)["traj"][2] == 0.0


def test_env_goal(env_tools):
    # Goal at 0.70 with tolerance 4 cm: a heel on the ground arriving at 0.69 is in it.
    out = env_tools.run([0.66, 0.0], RIGHT)
    assert out["traj"][3] == 10.0
    assert out["terminated"] and bool(out["info"]["goal_reached"])
    miss = env_tools.run([0.60, 0.0], RIGHT)
    assert miss["traj"][3] == 0.0 and not miss["terminated"]


def test_env_mid_goal(env_tools):
    # Mid-goal box: centre (0.45, 0.20), half sizes (0.06, 0.05): far edge at y = 0.51.
    out = env_tools.run([0.50, 0.30], RIGHT)  # heel at 0.53, never went through the box
    assert out["traj"][4] == -1.0
    visited = env_tools.run([0.50, 0.30], RIGHT, visited=True)
    assert visited["traj"][4] == 0.0
    inside = env_tools.run([0.42, 0.20], RIGHT)  # into the box at (0.45, 0.20): visited
    assert inside["traj"][4] == 0.0 and bool(inside["state"].visited_mid)


def test_env_max_height(env_tools):
    # max_z = 0.10 + 0.20 = 0.30; going up to 0.32 before the mid-goal: only r5 (and r0) fire.
    out = env_tools.run([0.20, 0.29], UP)
    assert out["traj"][5] == -1.0
    assert out["traj"][7] == 0.0
    assert env_tools.run([0.20, 0.25], UP)["traj"][5] == 0.0


def test_env_safety(env_tools):
    # Toe at 0.33 at z = 0.05: 2 cm before Base 1's near side (< 3 cm), no contact.
    out = env_tools.run([0.10, 0.05], RIGHT)
    assert float(out["info"]["clearance"]) == pytest.approx(0.02, abs=1e-5)
    assert out["traj"][6] == -2.0 and out["traj"][1] == 0.0
    assert env_tools.run([0.05, 0.05], RIGHT)["traj"][6] == 0.0  # 7 cm away


def test_env_z_monotone(env_tools):
    assert env_tools.run([0.20, 0.10], DOWN)["traj"][7] == -0.5  # falling before the mid-goal
    assert env_tools.run([0.60, 0.10], UP)["traj"][7] == -0.5  # rising after it
    assert env_tools.run([0.60, 0.10], DOWN)["traj"][7] == 0.0


def test_env_hip_lowering(env_tools):
    from jaxexo.physics.geometry import Obstacle

    # Pivot at the agent's start (y = 0), heel moved to 0.90: dist_y 0.45, h_z = sqrt(1 - 0.45^2) < 0.9.
    out = env_tools.run([0.87, 0.0], RIGHT, obstacle=Obstacle.named("base1"), pivot="agent")
    hz = math.sqrt(1 - 0.45**2)
    assert out["exo"][0] == pytest.approx(-1.0 / hz, rel=1e-5)
    np.testing.assert_allclose(np.asarray(out["info"]["hip"]), [0.45, hz], atol=1e-5)
    assert env_tools.run([0.60, 0.0], RIGHT, pivot="agent")["exo"][0] == 0.0


def test_env_leg_length(env_tools):
    # A pivot given in metres, 1.0 m behind the start; the heel at 1.2: heels 2.2 m apart
    # (> two legs), the hip is clamped low and both legs are over-stretched.
    out = env_tools.run([1.17, 0.0], RIGHT, pivot=-1.0)
    assert out["exo"][1] == -1.0
    assert bool(out["info"]["leg_length_violation"])
    assert env_tools.run([0.0, 0.0], RIGHT, pivot=-1.0)["exo"][1] == 0.0


def test_env_joint_limits(env_tools):
    # Pivot under the hip at 0.45, heel lifted to (0.45, 0.70): |hip - heel| = 0.3, the knee
    # flexes by about 145 deg, beyond the 100 deg limit.
    out = env_tools.run([0.45, 0.67], UP)
    assert out["exo"][2] == -1.0
    q = np.asarray(out["info"]["joint_angles"])
    assert q[1] == pytest.approx(-(math.pi - 2 * math.asin(0.15 / 0.5)), abs=1e-3)
    assert bool(out["info"]["joint_limit_violation"])
    assert env_tools.run([0.45, 0.10], UP)["exo"][2] == 0.0


def test_env_hip_height(env_tools):
    # The hip model never exceeds t + s = 1.0, so lower max_hip_z to make eq 2.51 fire.
    p = env_tools.params.replace(max_hip_z=env_tools.params.max_hip_z * 0 + 0.99)
    out = env_tools.run([0.42, 0.0], RIGHT, p=p)  # heel at the pivot's y: hip at 1.0
    assert out["exo"][3] == -1.0
    assert env_tools.run([0.42, 0.0], RIGHT)["exo"][3] == 0.0  # default max_hip_z = 1.0


# --------------------------------------------------------------------------------------------
# The wearer's costs (not in the thesis): lift above what the clearance needs, and move time
# --------------------------------------------------------------------------------------------


def _two_link_angles(hip, heel, thigh, shin):
    """Reference hip and knee angles of one leg by the law of cosines (independent of kinematics.py):
    hip angle from the downward vertical, positive forward; knee <= 0 in flexion."""
    d = np.asarray(heel, float) - np.asarray(hip, float)
    r = min(float(np.hypot(*d)), thigh + shin)
    to_heel = math.atan2(d[0], -d[1])  # from the downward vertical, forward +
    inner = math.acos(np.clip((thigh**2 + r**2 - shin**2) / (2 * thigh * r), -1, 1))
    knee = -(math.pi - math.acos(np.clip((thigh**2 + shin**2 - r**2) / (2 * thigh * shin), -1, 1)))
    return to_heel + inner, knee


def test_wearer_lift_by_hand():
    from jaxexo.physics.rewards import WEARER_TERMS, wearer_terms

    assert WEARER_TERMS == ("lift", "move_time", "turn")
    c = SimpleNamespace(shield_clearance=0.025, joint_speed=np.array([3.0, 4.0, 3.0, 4.0]))
    heel = np.array([[0.4, 0.10], [0.4, 0.125], [0.4, 0.165], [0.9, 0.0]])
    out = wearer_terms(
        np,
        c,
        heel=heel,
        top=np.full(4, 0.10),
        angles_prev=np.zeros((4, 4)),
        angles=np.zeros((4, 4)),
    )
    # below top + clearance: nothing; 4 cm above it: -0.04; no joint motion: no time
    np.testing.assert_allclose(out[:, 0], [0.0, 0.0, -0.04, 0.0], atol=1e-12)
    np.testing.assert_array_equal(out[:, 1], np.zeros(4))
    np.testing.assert_array_equal(out[:, 2], np.zeros(4))  # no turn given: none counted


def test_wearer_turn_by_hand():
    """A move's turn is 1 - cos of its angle to the last move: 0 straight on, 1 at a right angle, 2
    reversed, 1 - cos(10 deg) for the neighbouring direction; none at the first move."""
    from jaxexo.physics import actions
    from jaxexo.physics.rewards import turn_of

    dirs = actions.action_directions()
    a = np.array([0, 9, 27, 1, 35, 4])
    last = np.array([0, 0, 9, 0, 0, -1])
    np.testing.assert_allclose(
        turn_of(np, dirs, a, last),
        [0.0, 1.0, 2.0, 1 - math.cos(math.radians(10)), 1 - math.cos(math.radians(10)), 0.0],
        atol=1e-12,
    )


def test_wearer_move_time_matches_two_link_reference(env_tools):
    """Through the environment: a move's time is the largest |dq| / v_max over both legs' hip and knee,
    against a law-of-cosines reference of the joint angles at both ends."""
    from jaxexo.physics import kinematics

    p = env_tools.params
    thigh, shin = float(p.thigh), float(p.shin)
    for heel, action in (([0.30, 0.10], UP), ([0.20, 0.05], RIGHT), ([0.50, 0.20], DOWN)):
        out = env_tools.run(heel, action)
        new = np.asarray(out["info"]["heel"], float)
        pivot = float(out["state"].layout.pivot_y)
        q = []
        for h in (np.asarray(heel, float), new):
            hip = np.asarray(kinematics.hip_position(np, np.float64(pivot), h, thigh, shin), float)
            sw = _two_link_angles(hip, h, thigh, shin)
            st = _two_link_angles(hip, [pivot, 0.0], thigh, shin)
            q.append(np.array([sw[0], sw[1], st[0], st[1]]))
        speed = np.array([3.0, 4.0, 3.0, 4.0])  # the config's [device] defaults (hip, knee) x 2
        expected = np.max(np.abs(q[1] - q[0]) / speed)
        got = -float(np.asarray(out["info"]["wearer_terms"])[1])
        assert expected > 0.003
        assert got == pytest.approx(expected, rel=2e-3, abs=2e-5)


def test_wearer_costs_enter_the_reward(env_tools):
    """lift_cost and time_cost weigh the wearer's terms in the reward (0: the thesis reward)."""
    p0 = env_tools.params
    base = env_tools.run([0.40, 0.20], UP)
    p1 = p0.replace(
        lift_cost=p0.lift_cost + 10.0, time_cost=p0.time_cost + 2.0, turn_cost=p0.turn_cost + 3.0
    )
    base = env_tools.run([0.40, 0.20], UP, last=RIGHT)
    out = env_tools.run([0.40, 0.20], UP, p=p1, last=RIGHT)
    w = np.asarray(out["info"]["wearer_terms"])
    assert w[0] < 0 and w[1] < 0 and w[2] == pytest.approx(-1.0, abs=1e-6)  # a right-angle turn
    assert out["reward"] - base["reward"] == pytest.approx(
        10.0 * w[0] + 2.0 * w[1] + 3.0 * w[2], rel=1e-4, abs=1e-6
    )
