"""The legs in MuJoCo (jaxexo.sim): the MJCF against the config, the obstacle's convex pieces against
jaxexo's inside test, MuJoCo's distance against hand-made poses, a swing through the obstacle reported
as a contact, and bad input refused before MuJoCo is called."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from jaxexo.config import load_config, scalar_params
from jaxexo.physics import geometry, scenarios
from jaxexo.physics.geometry import GeometryError, Obstacle
from jaxexo.physics.scene import make_scene
from jaxexo.sim.mjcf import SimError, legs_mjcf, scene_mjcf
from jaxexo.sim.pieces import convex_pieces

from conftest import ROOT

mujoco = pytest.importorskip("mujoco")

from jaxexo.sim.replay import (
    Legs,
    brute_force_distance,
    driven_replay,
    feed_forward,
    hermite,
    interpolate,
    kinematic_replay,
    reference_states,
)  # noqa: E402


@pytest.fixture(scope="module")
def config():
    cfg = load_config(ROOT / "configs" / "default.toml")
    # Unequal lengths and limits unlike the defaults, so that a mix-up shows.
    return dataclasses.replace(
        cfg,
        kinematics=dataclasses.replace(
            cfg.kinematics,
            thigh=0.46,
            shin=0.53,
            foot_length=0.22,
            hip_limits=(-0.6, 1.9),
            knee_limits=(-1.6, 0.05),
        ),
    )


def _scene(config, obstacle, pivot="between"):
    return make_scene(obstacle, pivot, 0.0, 0.70, foot_length=config.kinematics.foot_length)


def test_mjcf_links_and_limits_are_the_configs(config):
    m = mujoco.MjModel.from_xml_string(legs_mjcf(config, Obstacle.named("triangle").outline, 0.3))
    k, dev = config.kinematics, config.device
    name = lambda kind, n: mujoco.mj_name2id(m, kind, n)  # noqa: E731
    for leg in ("right", "left"):
        assert m.body_pos[name(mujoco.mjtObj.mjOBJ_BODY, f"{leg}_shin")][2] == pytest.approx(
            -k.thigh, abs=1e-12
        )
        assert m.body_pos[name(mujoco.mjtObj.mjOBJ_BODY, f"{leg}_foot")][2] == pytest.approx(
            -k.shin, abs=1e-12
        )
        toe = m.site_pos[name(mujoco.mjtObj.mjOBJ_SITE, f"{leg}_toe")]
        assert toe[0] == pytest.approx(k.foot_length, abs=1e-12)
        np.testing.assert_allclose(
            m.jnt_range[name(mujoco.mjtObj.mjOBJ_JOINT, f"{leg}_hip")], k.hip_limits, atol=1e-12
        )
        np.testing.assert_allclose(
            m.jnt_range[name(mujoco.mjtObj.mjOBJ_JOINT, f"{leg}_knee")], k.knee_limits, atol=1e-12
        )
    (vh, vk), (ah, ak) = dev.joint_velocity, dev.joint_acceleration
    np.testing.assert_allclose(m.numeric("device_joint_velocity").data, [vh, vk, vh, vk])
    np.testing.assert_allclose(m.numeric("device_joint_acceleration").data, [ah, ak, ah, ak])
    assert m.nu == 4


def test_keyframe_puts_the_feet_where_jaxexo_does(config):
    sc = _scene(config, Obstacle.named("base2"))
    m = mujoco.MjModel.from_xml_string(scene_mjcf(config, sc))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    site = lambda n: d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n)][[0, 2]]  # noqa: E731
    # 1e-7: jaxexo's angles come from the float32 scalar parameters (jaxexo.config.scalar_params),
    # which round this config's 0.46 m and 0.53 m by ~1e-8 m; the model has the float64 lengths.
    np.testing.assert_allclose(site("right_heel"), [sc.start_y, 0.0], atol=1e-7)
    np.testing.assert_allclose(
        site("right_toe"), [sc.start_y + config.kinematics.foot_length, 0.0], atol=1e-7
    )
    np.testing.assert_allclose(site("left_heel"), [sc.pivot_y, 0.0], atol=1e-7)


def _inside_piece(p, poly):
    """Inside a counter-clockwise convex polygon (or on its boundary): left of every edge."""
    a, b = poly, np.roll(poly, -1, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (p[:, None, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (
        p[:, None, 0] - a[:, 0]
    )
    return np.all(cross >= -1e-15, axis=1)


def test_convex_pieces_cover_the_outline_exactly():
    rng = np.random.default_rng(0)
    outlines = [Obstacle.named(k).outline for k in geometry.THESIS_OBSTACLES]
    outlines += [s.obstacle.outline for s in scenarios.unseen_scenarios(0.2, 1)[::9]]
    for o in outlines:
        pieces = convex_pieces(o)
        lo, hi = o.min(axis=0), o.max(axis=0)
        p = rng.uniform(lo - 0.01, hi + 0.01, size=(4000, 2))
        inside = geometry.point_in_obstacle(np, p, o)
        in_pieces = np.zeros(len(p), dtype=bool)
        for poly in pieces:
            in_pieces |= _inside_piece(p, poly)
        # Points on a boundary may go either way; none of 4000 random points lands on one.
        assert np.array_equal(inside, in_pieces)
    assert (
        len(convex_pieces(Obstacle.named("half_circle").outline)) == 1
    )  # a convex outline is one piece


@pytest.mark.parametrize(
    "points, match",
    [
        ([[0.0, 0.0], [0.0, 0.1], [0.0, 0.05], [0.1, 0.05], [0.1, 0.0]], "fold back"),
        ([[0.0, 0.0], [0.05, 0.1], [0.1, 0.0], [0.15, 0.1], [0.2, 0.0]], "touches the ground"),
        ([[0.0, 0.0], [0.1, 0.1], [0.05, 0.1], [0.2, 0.0]], "backwards"),
    ],
)
def test_an_outline_that_is_not_a_simple_polygon_is_refused(config, points, match):
    with pytest.raises(GeometryError, match=match):
        legs_mjcf(config, np.asarray(points), 0.3)


def test_a_config_whose_legs_cannot_be_built_is_refused(config):
    bad = dataclasses.replace(config, kinematics=dataclasses.replace(config.kinematics, shin=0.0))
    with pytest.raises(SimError, match="kinematics.shin"):
        legs_mjcf(bad)
    bad = dataclasses.replace(
        config, kinematics=dataclasses.replace(config.kinematics, knee_limits=(0.1, -0.5))
    )
    with pytest.raises(SimError, match="kinematics.knee_limits"):
        legs_mjcf(bad)


def _hand_made(config, scene, heel: np.ndarray, rate: float = 100.0):
    """A TimedSwing of a hand-made heel path (N, 2), timed for the device."""
    from jaxexo.inference import assemble
    from jaxexo.swing.timing import time_swing

    sp = scalar_params(config)
    batch = assemble("hand", sp, [scene], [heel], heel[None], smoothing=[0.0], deviation=[0.0])
    return time_swing(batch[0], config, rate=rate)


def _over(scene, height: float) -> np.ndarray:
    """A heel path straight up from the start to ``height``, level to above the goal, straight down."""
    up = np.linspace(0.0, height, 12)
    level = np.linspace(scene.start_y, scene.goal_y, 40)[1:-1]
    return np.concatenate(
        [
            np.column_stack([np.full(12, scene.start_y), up]),
            np.column_stack([level, np.full(len(level), height)]),
            np.column_stack([np.full(12, scene.goal_y), up[::-1]]),
        ]
    )


def test_a_pose_at_a_known_distance_measures_it(config):
    sc = _scene(config, Obstacle.rectangle(0.10, 0.08, center_y=0.40))
    legs = Legs(config, sc)
    from jaxexo.swing.timing import leg_angles

    sp = scalar_params(config)
    for heel, want in (
        ((0.25, 0.08 + 0.037), 0.037),  # above the top
        ((0.05, 0.02), 0.35 - 0.05 - 0.22),  # on the ground's level, toe short of the side
        ((0.46, 0.09), 0.01),
    ):  # heel past the right edge's corner: vertex distance
        heel = np.asarray(heel)
        if want == 0.01:
            want = float(np.hypot(0.46 - 0.45, 0.09 - 0.08))
        legs.set_pose(legs.qpos(leg_angles(sp, sc.pivot_y, heel[None])[0]))
        np.testing.assert_allclose(
            legs.site_yz("right_heel"), heel, atol=1e-7
        )  # float32 scalar params
        assert abs(legs.foot_distance() - want) < 1e-6
        assert (
            abs(brute_force_distance(heel, config.kinematics.foot_length, sc.outline) - want) < 1e-9
        )


def test_a_hand_made_swing_at_a_known_distance_measures_it(config):
    sc = _scene(config, Obstacle.rectangle(0.10, 0.08, center_y=0.40))
    heel = _over(sc, 0.08 + 0.045)
    timed = _hand_made(config, sc, heel)
    r = kinematic_replay(timed, config, substeps=1)
    # The level stretch passes over the whole top: the smallest distance is the 4.5 cm gap.
    assert abs(r.mujoco_min_distance_m - 0.045) < 1e-6
    assert r.max_disagreement_m < 1e-6
    assert r.max_heel_offset_m < 1e-7


def test_a_swing_through_the_obstacle_is_a_contact(config):
    sc = _scene(config, Obstacle.rectangle(0.10, 0.08, center_y=0.40))
    timed = _hand_made(
        config, sc, _over(sc, 0.04)
    )  # half the obstacle's height: straight through it
    assert not timed.ok
    k = kinematic_replay(timed, config)
    assert k.mujoco_min_distance_m <= 0.0 and not k.margin_kept
    d = driven_replay(timed, config, settle=0.0)
    assert d.figures.contact and d.figures.contact_steps > 0


def test_a_safe_swing_tracks_at_the_limits_and_keeps_clear(config):
    from jaxexo.baselines import CFFTG
    from jaxexo.swing.timing import time_swing

    traj = CFFTG(config).generate(Obstacle.named("base1"), pivot="between")
    timed = time_swing(traj, config, rate=100.0)
    assert timed.ok
    k = kinematic_replay(timed, config)
    assert k.margin_kept and k.max_disagreement_m < 1e-6
    # Between the samples the legs are posed on the curve: MuJoCo's own distance never falls below
    # jaxexo's guaranteed clearance (with linear joint interpolation between 100 Hz samples it did,
    # by 0.1 mm on some of 6,000 swings).
    assert k.mujoco_min_distance_m >= timed.checks.min_clearance - 1e-6
    d = driven_replay(timed, config, settle=0.05)
    assert not d.figures.contact
    assert d.figures.heel_error_max_m < 0.10 and d.figures.stance_heel_slip_max_m < 0.005
    # At a tenth of the limits the drive cannot follow: a limit saturates.
    slow = driven_replay(timed, config, limits=timed.limits.scaled(0.1, 0.1), settle=0.0)
    assert slow.figures.saturated and slow.figures.heel_error_max_m > d.figures.heel_error_max_m


def test_feed_forward_torques_alone_carry_the_legs_along_the_reference(config):
    """The feed-forward torques, applied open loop in MuJoCo's forward simulation (its own soft
    stance and level constraints, no feedback), carry the legs along the reference for 40 ms from
    any reference state, where gravity alone lets them drift away: an independent check of the
    rigid inverse dynamics in feed_forward."""
    from jaxexo.baselines import CFFTG
    from jaxexo.sim.driven import _equalities_on
    from jaxexo.swing.timing import time_swing

    timed = time_swing(
        CFFTG(config).generate(Obstacle.named("base2"), pivot="between"), config, rate=100.0
    )
    legs = Legs(config, timed.scene)
    _equalities_on(legs)
    m, d = legs.model, legs.data
    dt = m.opt.timestep = 1e-3
    q = hermite(
        timed.joint_angles, timed.joint_velocity, 0.01, np.arange(len(timed.joint_angles) * 10) * dt
    )
    qpos = legs.qpos(q)
    qvel = np.gradient(qpos, dt, axis=0, edge_order=2)
    qacc = np.gradient(qvel, dt, axis=0, edge_order=2)
    tau = feed_forward(legs, qpos, qvel, qacc)
    act = legs.actuated_dofs
    m.opt.disableflags |= int(
        mujoco.mjtDisableBit.mjDSBL_ACTUATION
    )  # the torques alone move the legs
    span = 40
    for k in range(20, len(qpos) - span - 20, 150):
        drift = {}
        for label, scale in (("ff", 1.0), ("none", 0.0)):
            mujoco.mj_resetData(m, d)
            d.qpos[:], d.qvel[:] = qpos[k], qvel[k]
            for i in range(span):
                d.qfrc_applied[:] = 0.0
                d.qfrc_applied[act] = scale * tau[k + i]
                mujoco.mj_step(m, d)
            drift[label] = float(np.abs(d.qpos[act] - qpos[k + span][act]).max())
        assert drift["ff"] < 0.01 and drift["ff"] < 0.1 * drift["none"], (k, drift)


def test_feed_forward_tracks_where_a_plain_servo_lags(config):
    """With the same setpoints, the PD with feed-forward keeps the heel within millimetres of the
    swing; the plain position servo trails it by about 2 / omega times the joints' speed."""
    from jaxexo.baselines import CFFTG
    from jaxexo.swing.timing import time_swing

    timed = time_swing(
        CFFTG(config).generate(Obstacle.named("base1"), pivot="between"), config, rate=100.0
    )
    ff = driven_replay(timed, config, settle=0.05)
    servo = driven_replay(timed, config, settle=0.05, controller="servo")
    assert ff.controller == "pd_ff" and servo.controller == "servo"
    assert ff.figures.heel_error_max_m < 0.005 < servo.figures.heel_error_max_m
    assert (
        not ff.figures.contact
        and ff.figures.margin_kept
        and ff.figures.stance_heel_slip_max_m < 0.005
    )
    with pytest.raises(SimError, match="controller"):
        driven_replay(timed, config, controller="pid")


def test_jaxexo_and_its_inference_never_import_mujoco():
    code = (
        "import sys, jaxexo, jaxexo.inference, jaxexo.sim, jaxexo.sim.mjcf; "
        "assert 'mujoco' not in sys.modules, 'mujoco imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_cli_mjcf_writes_a_model_mujoco_loads(tmp_path, config):
    from jaxexo.cli import main

    out = tmp_path / "legs.xml"
    assert main(["mjcf", "--obstacle", "triangle", "--pivot", "between", "--out", str(out)]) == 0
    m = mujoco.MjModel.from_xml_path(str(out))
    assert m.nkey == 1 and m.nu == 4


def test_eval_replay_figures_count_the_swings(config):
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.compare import mujoco_lines
    from jaxexo.sim.replay import replay_trajectories
    from jaxexo.swing.timing import time_swings

    gen = CFFTG(config)
    trajs = [gen.generate(Obstacle.named(k), pivot="obstacle") for k in ("base1", "triangle")]
    r = replay_trajectories(trajs, config)
    ok = sum(t.ok for t in time_swings(trajs, config))
    assert r["kinematic"]["n"] == 2 and r["kinematic"]["flagged_ok"] == ok == r["driven"]["n"]
    assert r["kinematic"]["flagged_ok_within_margin"] == 0 and r["driven"]["contacts"] == 0
    lines = mujoco_lines({"cfftg": {"mujoco": r}}, 100.0)
    assert lines[-1].startswith(f"| cfftg | 2 | {ok} | 0 |")


def test_quintic_hermite_reproduces_a_quintic_and_meets_the_samples():
    """From a quintic's positions, velocities and accelerations at the samples, the quintic Hermite
    is that quintic everywhere (each joint its own), and meets every sample's three values."""
    rng = np.random.default_rng(5)
    coef = rng.normal(size=(6, 4))  # q_j(t) = sum_k coef[k, j] t^k
    powers = lambda t, d: np.stack(  # noqa: E731
        [
            np.where(k >= d, np.prod(np.arange(k - d + 1, k + 1)) * t ** max(k - d, 0), 0.0)
            for k in range(6)
        ],
        axis=1,
    )
    exact = lambda t, d: powers(t, d) @ coef  # noqa: E731
    period = 0.013
    knots = np.arange(9) * period
    samples = (exact(knots, 0), exact(knots, 1), exact(knots, 2))
    t = np.linspace(0.0, knots[-1], 997)
    for d, got in enumerate(interpolate("quintic", samples, period, t)):
        np.testing.assert_allclose(got, exact(t, d), rtol=1e-9, atol=1e-9)
    for d, got in enumerate(interpolate("quintic", samples, period, knots)):
        np.testing.assert_allclose(got, samples[d], rtol=1e-12, atol=1e-12)
    # The cubic Hermite meets the positions and velocities, not the accelerations; linear only
    # the positions.
    cubic = interpolate("cubic", samples, period, knots[:-1])
    np.testing.assert_allclose(cubic[0], samples[0][:-1], atol=1e-12)
    np.testing.assert_allclose(cubic[1], samples[1][:-1], atol=1e-12)
    np.testing.assert_allclose(
        interpolate("linear", samples, period, knots)[0], samples[0], atol=1e-12
    )
    np.testing.assert_array_equal(
        hermite(samples[0], samples[1], period, t), interpolate("cubic", samples, period, t)[0]
    )


def _cfftg_swing(config, name="base1", rate=100.0):
    from jaxexo.baselines import CFFTG
    from jaxexo.swing.timing import time_swing

    return time_swing(CFFTG(config).generate(Obstacle.named(name), pivot="between"), config, rate)


def test_the_curve_reference_is_the_curve_at_every_physics_step(config):
    """reference="curve": the setpoints follow timed.at at every physics step, position, velocity
    and acceleration; a sampled reference meets the samples at theirs."""
    from jaxexo.sim.driven import _simulate

    timed = _cfftg_swing(config, "base2")
    legs = Legs(config, timed.scene)
    run = _simulate(timed, legs, timed.limits, 0.02, "pd_ff", "curve", None)
    t = np.arange(run.steps + 2) * run.dt
    assert run.dt <= 1e-3 and len(run.reference) == len(t)
    st = timed.at(t)
    np.testing.assert_array_equal(run.reference, st.joint_angles)
    got = reference_states(timed, t, "curve")
    for a, b in zip(got, (st.joint_angles, st.joint_velocity, st.joint_acceleration)):
        np.testing.assert_array_equal(a, b)
    # Between the samples the curve is not the straight line: the references differ there.
    lin = reference_states(timed, t, "linear", 100.0)[0]
    assert np.abs(lin - st.joint_angles).max() > 1e-4
    sw = timed.sample(500.0)
    for kind in ("quintic", "cubic", "linear"):
        q = reference_states(timed, sw.time[:-1], kind, 500.0)[0]
        np.testing.assert_allclose(q, sw.joint_angles[:-1], atol=1e-12)


@pytest.mark.parametrize("name", ["base1", "triangle"])
def test_a_driven_replay_of_the_curve_tracks_without_clipping(config, name):
    """pd_ff on the curve: the heel within 2.5 mm of the swing at every sample (the figure is
    about 1.6 mm, mostly the soft stance constraint's give), no setpoint clipped, clear of the
    obstacle; the quintic of 500 Hz samples and the cubic of 1 kHz samples track as well."""
    timed = _cfftg_swing(config, name)
    assert timed.ok
    legs = Legs(config, timed.scene)
    d = driven_replay(timed, config, legs=legs, settle=0.05)
    assert d.reference == "curve" and d.reference_rate_hz is None
    assert d.figures.heel_error_max_m < 0.0025 and d.figures.heel_error_p95_m < 0.0025
    assert not d.figures.saturated and d.figures.saturated_acceleration_steps == 0
    assert (
        not d.figures.contact and d.figures.margin_kept and d.figures.stance_heel_slip_max_m < 0.005
    )
    for kind, rate in (("quintic", 500.0), ("cubic", 1000.0)):
        s = driven_replay(
            timed, config, legs=legs, settle=0.05, reference=kind, reference_rate=rate
        )
        assert s.reference == kind and s.reference_rate_hz == rate
        assert not s.figures.saturated and not s.figures.contact
        assert abs(s.figures.heel_error_max_m - d.figures.heel_error_max_m) < 2e-4


def test_a_bad_reference_is_refused_naming_the_argument(config):
    timed = _cfftg_swing(config)
    for kwargs, match in (
        ({"reference": "spline"}, "reference: expected one of curve, quintic, cubic, linear"),
        ({"reference": "curve", "reference_rate": 500.0}, "reference_rate: only for the sampled"),
        ({"reference": "quintic", "reference_rate": 1e6}, "reference_rate: control rate"),
        ({"reference": "cubic", "reference_rate": "fast"}, "reference_rate: expected a number"),
    ):
        with pytest.raises(SimError, match=match):
            driven_replay(timed, config, **kwargs)
    with pytest.raises(SimError, match="reference: 'curve' needs"):
        driven_replay(dataclasses.replace(timed, curve=None), config)
    with pytest.raises(TypeError):
        driven_replay(timed, config, None, None, 0.0, "pd_ff", "curve")  # keyword-only
