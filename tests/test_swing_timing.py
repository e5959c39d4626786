"""Device-ready swings (jaxexo.swing.timing): joint velocity and acceleration limits held on
the exported samples (checked here by finite differences of the exported positions, independently
of the module's own columns), rest at both ends, samples on the path, durations that scale with the
limits, a shorter swing than a fixed-shape (quintic) time law found by brute force, config and
argument errors, exports and the CLI."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.config import Config, ConfigError, config_from_dict, load_config, scalar_params
from jaxexo.config.toml_io import config_to_toml
from jaxexo.inference import Obstacle
from jaxexo.physics import kinematics
from jaxexo.physics.scene import make_scene
from jaxexo.swing.export import TIMED_CSV_COLUMNS
from jaxexo.swing.timing import DeviceLimits, time_swing, time_swings, uniform_peaks
from jaxexo.swing.trajectory import assemble

from conftest import ROOT, legacy_raw, recorded_swing

CFG = load_config(ROOT / "configs" / "default.toml")
SP = scalar_params(CFG)
THESIS = ("base1", "base2", "base3", "triangle", "half_circle")


def fd(q, rate):
    """Independent check: finite differences of exported positions at the control rate."""
    dt = 1.0 / rate
    return np.diff(q, axis=0) / dt, np.diff(q, n=2, axis=0) / dt**2


def assert_device_ready(sw, limits: DeviceLimits, rate: float):
    vmax, amax = np.array(limits.velocity), np.array(limits.acceleration)
    v, a = fd(sw.joint_angles, rate)
    assert np.all(np.abs(v) <= vmax), (np.abs(v).max(0), vmax)
    assert np.all(np.abs(a) <= amax), (np.abs(a).max(0), amax)
    assert np.all(np.abs(sw.joint_velocity) <= vmax) and np.all(
        np.abs(sw.joint_acceleration) <= amax
    )
    assert sw.within_limits
    # Rest at lift-off and touch-down: zero velocity and acceleration, and the positions barely move
    # over the first and last control period (s ~ t^3 there).
    for end in (0, -1):
        assert np.all(sw.joint_velocity[end] == 0) and np.all(sw.joint_acceleration[end] == 0)
    assert np.all(np.abs(v[[0, -1]]) <= 0.05 * vmax)
    assert np.all(np.abs(a[[0, -1]]) <= 0.5 * amax)
    # Uniform control periods from 0 to the duration.
    assert sw.time[0] == 0 and sw.time[-1] == pytest.approx(sw.duration)
    np.testing.assert_allclose(np.diff(sw.time), 1.0 / rate, rtol=1e-9)


def random_path(rng, n=100, dense=None):
    """A random smooth swing (n, 2) from (0, 0) to (0.70, 0), z >= 0; with ``dense``, also the same
    curve at that many points (the reference for "on the path")."""
    k = np.arange(1, 4)[:, None]
    cy, h, cz, p = (
        rng.uniform(-0.03, 0.03, (3, 1)),
        rng.uniform(0.05, 0.30),
        rng.uniform(-0.01, 0.01, (3, 1)),
        rng.uniform(0.6, 2.0),
    )

    def curve(tau):
        y = 0.70 * tau + (cy * np.sin(k * np.pi * tau)).sum(0)
        z = (h + (cz * np.sin(k * np.pi * tau)).sum(0)) * np.sin(np.pi * tau) ** p
        return np.column_stack([y, z])

    path = curve(np.linspace(0.0, 1.0, n))
    return path if dense is None else (path, curve(np.linspace(0.0, 1.0, dense)))


def synthetic(paths, pivot="between"):
    ob = Obstacle.rectangle(0.05, 0.05, center_y=0.45)
    scenes = [make_scene(ob, pivot, 0.0, 0.70, foot_length=SP.foot_length) for _ in paths]
    return list(
        assemble(
            "test",
            SP,
            scenes,
            list(paths),
            np.stack(paths),
            [float("nan")] * len(paths),
            deviation=np.zeros(len(paths)),
        )
    )  # the paths are the polylines themselves


def test_limits_hold_on_random_paths_and_ends_rest():
    rng = np.random.default_rng(3)
    trajs = synthetic([random_path(rng) for _ in range(12)])
    lim = DeviceLimits.from_config(CFG)
    for rate in (100.0, 500.0):
        for sw in time_swings(trajs, CFG, rate=rate):
            assert_device_ready(sw, lim, rate)
            # The passes and their local corrections, not the uniform slow-down, set the timing,
            # at every rate alike (the limits are held on the curve, not on the samples).
            assert sw.slowdown < 1.1


def test_the_safety_net_slows_by_whole_control_periods():
    """Samples span whole control periods, so a uniform slow-down of less than one period exports the
    same samples again: the net must add at least a period. The recorded swing (tests/data) came out
    of the TOPP passes 0.13 % over the hip's acceleration limit at 100 Hz, and was left flagged not
    within the limits when the net's slow-downs stayed inside one period."""
    rec = json.loads((ROOT / "tests" / "data" / "stuck_swing.json").read_text())
    traj = recorded_swing(SP, rec)
    planned = DeviceLimits.from_config(CFG).planned()
    sw = time_swing(traj, CFG, rate=100.0)
    v, a = fd(sw.joint_angles, 100.0)
    assert sw.within_limits and sw.slowdown > 1.0
    assert np.all(np.abs(v) <= planned.velocity) and np.all(np.abs(a) <= planned.acceleration)
    assert np.all(np.abs(np.diff(a, axis=0) * 100.0) <= planned.jerk)
    assert np.all(np.abs(sw.joint_acceleration) <= planned.acceleration)


def test_limits_hold_on_polylines_with_corners():
    # The generator's last fallback is the raw polyline: corners in joint space, where the law must
    # nearly stop; the exported samples are held within the limits all the same.
    rng = np.random.default_rng(11)
    paths = []
    for _ in range(4):
        pts = np.array(
            [
                [0, 0],
                [0.1, rng.uniform(0.1, 0.25)],
                [0.45, rng.uniform(0.25, 0.35)],
                [0.62, rng.uniform(0.05, 0.15)],
                [0.70, 0.0],
            ]
        )
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        arc = np.concatenate([[0], np.cumsum(seg)])
        u = np.linspace(0, arc[-1], 100)
        paths.append(np.column_stack([np.interp(u, arc, pts[:, 0]), np.interp(u, arc, pts[:, 1])]))
    lim = DeviceLimits.from_config(CFG)
    for sw in time_swings(synthetic(paths), CFG, rate=100):
        assert_device_ready(sw, lim, 100)


def test_thesis_obstacles_and_unseen_shapes_cfftg():
    cf = CFFTG(CFG)
    obs = [Obstacle.named(k) for k in THESIS] + [
        Obstacle.rectangle(0.08, 0.25),
        Obstacle.triangle(0.22, 0.10),
        Obstacle.half_ellipse(0.18, 0.22),
        Obstacle.profile([(0.35, 0), (0.40, 0.15), (0.50, 0.08), (0.55, 0)]),
    ]
    batch = cf.generate_batch(obs, pivot=["agent", "obstacle", "between"] * 3)
    lim = DeviceLimits.from_config(CFG)
    for tr, sw in zip(batch, time_swings(batch, CFG, rate=200)):
        assert_device_ready(sw, lim, 200)
        assert sw.checks.ok == tr.checks.ok  # the exported samples pass the path's checks too
        assert sw.checks.min_clearance == pytest.approx(tr.checks.min_clearance, abs=2e-3)
        # The uniform 1 s timing of the same path asks for more than the device gives.
        assert uniform_peaks(tr)[0].max() > sw.peak_velocity.max()


def test_samples_lie_on_the_path():
    rng = np.random.default_rng(5)
    path, ref = random_path(rng, dense=10_000)
    (tr,) = synthetic([path])
    sw = time_swing(tr, CFG, rate=250)
    # The heel is the forward kinematics of the joints: the ends up to rounding.
    np.testing.assert_allclose(sw.heel[[0, -1]], tr.heel[[0, -1]], rtol=0, atol=1e-12)
    # Distance of every exported heel to the same curve sampled 100 times as densely (brute force).
    a, b = ref[:-1], ref[1:]
    d = b - a
    p = sw.heel[:, None, :]
    t = np.clip(np.sum((p - a) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-18), 0.0, 1.0)
    dist = np.linalg.norm(p - (a + t[..., None] * d), axis=-1).min(axis=1)
    # Between its 100 samples the joints follow a cubic spline, and where a leg straightens the
    # heel's monotone cubic through the samples (which flattens at extrema): 1 mm of the dense curve.
    assert dist.max() < 1e-3, dist.max()
    assert np.all(np.diff(sw.path_parameter) >= 0)  # forward along the path, never back
    # The exported points are the forward kinematics of the exported joints: segment lengths, the
    # pivot heel under the stance leg, and the swing leg's angles (independent: atan2 of the points).
    pivot = np.array([tr.scene.pivot_y, 0.0])
    for a, b, length in (
        (sw.hip, sw.knee_swing, SP.thigh),
        (sw.knee_swing, sw.heel, SP.shin),
        (sw.hip, sw.knee_stance, SP.thigh),
        (sw.knee_stance, pivot, SP.shin),
    ):
        np.testing.assert_allclose(np.linalg.norm(b - a, axis=1), length, rtol=0, atol=1e-12)
    hip, knee = kinematics.joint_angles(np, sw.hip, sw.knee_swing, sw.heel)
    np.testing.assert_allclose(np.c_[hip, knee], sw.joint_angles[:, :2], rtol=0, atol=1e-9)
    np.testing.assert_allclose(sw.toe[:, 0] - sw.heel[:, 0], SP.foot_length)
    # The heel's velocity column against central differences of the exported heel positions.
    cd = (sw.heel[2:] - sw.heel[:-2]) * 250 / 2
    np.testing.assert_allclose(sw.heel_velocity[1:-1], cd, atol=0.02 * np.abs(cd).max())
    assert np.all(sw.heel_velocity[[0, -1]] == 0) and np.all(sw.heel_acceleration[[0, -1]] == 0)


def test_durations_scale_with_the_limits():
    rng = np.random.default_rng(7)
    trajs = synthetic([random_path(rng) for _ in range(3)])
    # The velocity and acceleration law alone (jerk and headroom: test_jerk_limit_and_headroom_hold).
    base = dataclasses.replace(DeviceLimits.from_config(CFG), jerk=None, headroom=0.0)
    # Velocity-bound (accelerations practically unlimited): half the speed, twice the time.
    vb = base.scaled(acceleration=1e4)
    t1 = np.array([s.duration for s in time_swings(trajs, CFG, rate=200, limits=vb)])
    t2 = np.array(
        [s.duration for s in time_swings(trajs, CFG, rate=200, limits=vb.scaled(velocity=0.5))]
    )
    assert np.all((t2 / t1 > 1.85) & (t2 / t1 < 2.15)), t2 / t1
    # Acceleration-bound: a quarter of the acceleration, twice the time.
    ab = base.scaled(velocity=1e3)
    t3 = np.array([s.duration for s in time_swings(trajs, CFG, rate=200, limits=ab)])
    t4 = np.array(
        [s.duration for s in time_swings(trajs, CFG, rate=200, limits=ab.scaled(acceleration=0.25))]
    )
    assert np.all((t4 / t3 > 1.85) & (t4 / t3 < 2.15)), t4 / t3
    # A minimum duration is honoured (and the swing is still at rest at both ends).
    sw = time_swing(trajs[0], CFG, rate=100, limits=dataclasses.replace(base, min_duration=3.0))
    assert sw.duration == pytest.approx(3.0, abs=0.011)
    assert_device_ready(sw, base, 100)


def test_jerk_limit_and_headroom_hold_on_the_exported_samples():
    """The third finite difference of the exported angles stays within the jerk limit, and with a
    tracking headroom h every sample keeps (1 - h) of each limit; a velocity-bound swing then takes
    about 1 / (1 - h) as long."""
    rng = np.random.default_rng(5)
    trajs = synthetic([random_path(rng) for _ in range(4)])
    base = DeviceLimits.from_config(CFG)
    for jerk in (400.0, 1500.0):
        lim = dataclasses.replace(base, jerk=(jerk,) * 4, headroom=0.2)
        for sw in time_swings(trajs, CFG, rate=100, limits=lim):
            j = np.abs(np.diff(sw.joint_angles, n=3, axis=0)).max(0) * 100.0**3
            assert np.all(j <= 0.8 * jerk), (j, jerk)
            assert_device_ready(sw, base.scaled(0.8, 0.8), 100)
            assert sw.limits == lim and sw.within_limits
    vb = dataclasses.replace(base.scaled(acceleration=1e4), jerk=None, headroom=0.0)
    t0 = np.array([s.duration for s in time_swings(trajs, CFG, rate=200, limits=vb)])
    t1 = np.array(
        [
            s.duration
            for s in time_swings(trajs, CFG, rate=200, limits=dataclasses.replace(vb, headroom=0.2))
        ]
    )
    assert np.all((t1 / t0 > 1.15) & (t1 / t0 < 1.35)), t1 / t0
    for bad, match in (
        (dict(headroom=0.7), "limits.headroom"),
        (dict(headroom=-0.1), "limits.headroom"),
        (dict(jerk=(1.0, 2.0)), "limits.jerk"),
        (dict(jerk=(0.0,) * 4), "limits.jerk"),
    ):
        with pytest.raises(ValueError, match=match):
            dataclasses.replace(base, **bad)


def quintic_duration(tr, limits, rate=1000.0):
    """Brute-force reference: the shortest T for which the fixed rest-to-rest quintic time law
    s = 10 x^3 - 15 x^4 + 6 x^5 (x = t / T) along the path's polyline by arc length keeps the finite
    differences of the joint angles within the limits (bisection on T)."""
    seg = np.linalg.norm(np.diff(tr.heel, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()
    dense = np.linspace(0, 1, 20001)
    heel = np.column_stack(
        [np.interp(dense, arc, tr.heel[:, 0]), np.interp(dense, arc, tr.heel[:, 1])]
    )
    q = np.stack(
        list(
            getattr(kinematics.leg_state(np, tr.scene.pivot_y, heel, SP.thigh, SP.shin), k)
            for k in ("hip_swing", "knee_swing_angle", "hip_stance", "knee_stance_angle")
        ),
        -1,
    )
    vmax, amax = np.array(limits.velocity), np.array(limits.acceleration)

    def ok(T):
        x = np.linspace(0, 1, int(T * rate) + 1)
        s = 10 * x**3 - 15 * x**4 + 6 * x**5
        qs = np.stack([np.interp(s, dense, q[:, j]) for j in range(4)], -1)
        v, a = fd(qs, (len(x) - 1) / T)
        return np.all(np.abs(v) <= vmax) and np.all(np.abs(a) <= amax)

    lo, hi = 0.05, 20.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if ok(mid) else (mid, hi)
    return hi


def test_variable_speed_beats_a_fixed_time_law():
    cf = CFFTG(CFG)
    # Like with like: the quintic reference knows velocity and acceleration limits only, all of them.
    lim = dataclasses.replace(DeviceLimits.from_config(CFG), jerk=None, headroom=0.0)
    for kind in ("base2", "triangle"):
        tr = cf.generate(Obstacle.named(kind), pivot="between")
        t_opt = time_swing(tr, CFG, rate=1000, limits=lim).duration
        t_fixed = quintic_duration(tr, lim)
        assert t_opt < t_fixed, (kind, t_opt, t_fixed)


def test_exports_carry_velocities_accelerations_and_limits(tmp_path):
    tr = CFFTG(CFG).generate(Obstacle.named("base1"), pivot="agent")
    sw = time_swing(tr, CFG, rate=100)
    text = sw.to_csv(tmp_path / "s.csv")
    header = text.splitlines()[0].split(",")
    assert header == list(TIMED_CSV_COLUMNS)
    assert "hip_swing_vel_rad_s" in header and "knee_stance_acc_rad_s2" in header
    data = np.loadtxt(tmp_path / "s.csv", delimiter=",", skiprows=1)
    assert data.shape == (len(sw.time), len(TIMED_CSV_COLUMNS))
    np.testing.assert_allclose(
        data[:, header.index("knee_swing_vel_rad_s")], sw.joint_velocity[:, 1], rtol=1e-8, atol=1e-8
    )
    doc = json.loads(sw.to_json(tmp_path / "s.json"))
    assert doc["limits"]["joint_velocity_rad_s"] == list(CFG.device.joint_velocity) * 2
    assert doc["limits"]["joint_acceleration_rad_s2"] == list(CFG.device.joint_acceleration) * 2
    assert doc["rate_hz"] == 100 and doc["duration_s"] == pytest.approx(sw.duration)
    assert doc["checks"]["within_limits"] is True and len(doc["samples"]) == len(sw.time)


def test_device_config_section_and_bad_input():
    assert max(Config().device.joint_velocity) <= math.radians(300)
    cfg = config_from_dict(
        legacy_raw(
            {
                "device": {
                    "joint_velocity": [2.0, 2.5],
                    "joint_acceleration": [10, 12],
                    "min_swing_duration": 0.8,
                    "control_rate": 250,
                }
            }
        )
    )
    assert cfg.device.joint_velocity == (2.0, 2.5) and cfg.device.control_rate == 250.0
    import tomllib

    assert config_from_dict(tomllib.loads(config_to_toml(cfg))).device == cfg.device
    lim = DeviceLimits.from_config(cfg)
    assert lim.velocity == (2.0, 2.5, 2.0, 2.5) and lim.min_duration == 0.8
    with pytest.raises(ConfigError, match=r"device\.joint_velocity\[1\]"):
        config_from_dict(legacy_raw({"device": {"joint_velocity": [2.0, -1.0]}}))
    with pytest.raises(ConfigError, match=r"device\.joint_acceleration"):
        config_from_dict(legacy_raw({"device": {"joint_acceleration": [2.0]}}))
    cfg = config_from_dict(
        legacy_raw({"device": {"joint_jerk": [300.0, 500.0], "tracking_headroom": 0.2}})
    )
    lim = DeviceLimits.from_config(cfg)
    assert lim.jerk == (300.0, 500.0, 300.0, 500.0) and lim.headroom == 0.2
    assert lim.planned().velocity == pytest.approx(tuple(0.8 * v for v in lim.velocity))
    for bad, match in (
        ({"joint_jerk": [300.0, -1.0]}, r"device\.joint_jerk\[1\]"),
        ({"joint_jerk": [300.0]}, r"device\.joint_jerk"),
        ({"tracking_headroom": 0.9}, r"device\.tracking_headroom"),
        ({"tracking_headroom": float("nan")}, r"device\.tracking_headroom"),
    ):
        with pytest.raises(ConfigError, match=match):
            config_from_dict(legacy_raw({"device": bad}))
    with pytest.raises(ConfigError, match=r"device\.control_rate"):
        config_from_dict(legacy_raw({"device": {"control_rate": 0}}))
    with pytest.raises(ConfigError, match=r"device\.speed"):
        config_from_dict(legacy_raw({"device": {"speed": 1}}))
    with pytest.raises(ValueError, match=r"limits\.velocity"):
        DeviceLimits((1.0, 2.0, float("nan"), 1.0), (1.0,) * 4)
    with pytest.raises(ValueError, match=r"limits\.acceleration"):
        DeviceLimits((1.0,) * 4, (1.0, 2.0))
    with pytest.raises(ValueError, match=r"limits\.min_duration"):
        DeviceLimits((1.0,) * 4, (1.0,) * 4, -1.0)
    tr = CFFTG(CFG).generate(Obstacle.named("base1"))
    with pytest.raises(ValueError, match=r"rate"):
        time_swing(tr, CFG, rate=0.0)
    with pytest.raises(ValueError, match=r"heel"):
        time_swing(dataclasses.replace(tr, heel=tr.heel * np.nan), CFG)


def test_rl_swings_on_the_thesis_obstacles(trained_run):
    from jaxexo.inference import TrajectoryGenerator

    gen = TrajectoryGenerator.load(trained_run / "policy.npz")
    batch = gen.generate_batch(
        [Obstacle.named(k) for k in THESIS] * 3,
        pivot=[p for p in ("agent", "obstacle", "between") for _ in THESIS],
    )
    lim = DeviceLimits.from_config(gen.config)
    for tr, sw in zip(batch, time_swings(batch, gen.config, rate=100)):
        assert_device_ready(sw, lim, 100)
        assert sw.checks.collision_free == tr.checks.collision_free


@pytest.mark.slow
def test_cli_generate_rate_and_animation(trained_run, tmp_path):
    from jaxexo.cli import main

    out = tmp_path / "t.csv"

    def generate(rate, *more):
        """``jaxexo generate`` of the trained policy on Base 2 at ``rate`` Hz into t.csv (+ ``more``)."""
        args = ["--policy", trained_run / "policy.npz", "--obstacle", "base2", "--rate", rate]
        return main(["generate", *map(str, args), "--out", str(out), *map(str, more)])

    rc = generate(200, "--json", tmp_path / "t.json", "--animate", tmp_path / "s.gif")
    doc = json.loads((tmp_path / "t.json").read_text())
    assert rc == (0 if doc["checks"]["ok"] else 1)
    assert doc["rate_hz"] == 200 and doc["columns"] == list(TIMED_CSV_COLUMNS)
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape[1] == len(TIMED_CSV_COLUMNS) and data[-1, 0] == pytest.approx(
        doc["duration_s"]
    )
    from PIL import Image

    with Image.open(tmp_path / "s.gif") as im:
        assert im.n_frames >= 10
    assert generate(-5) == 2


def joint_passes(dq, ddq, vmax, amax):
    """The passes' rows and caps (limits.passes_rows) of joint velocity and acceleration limits for
    joint derivatives dq, ddq (B, K, J) (or (K, J): one path): (rows, cap (B, K))."""
    from jaxexo.swing.limits import GridView, JointAcceleration, JointVelocity, passes_rows

    if dq.ndim == 2:
        dq, ddq = dq[None], ddq[None]
    view = GridView(np.linspace(0.0, 1.0, dq.shape[1]), np.zeros_like(dq), dq, ddq)
    cap = np.full(dq.shape[:2], np.inf)
    cap, rows = passes_rows((JointVelocity(vmax), JointAcceleration(amax)), view, cap)
    return rows, cap


def _passes(dq, ddq, vmax, amax, ds, **kw):
    """time_law.topp of joint velocity and acceleration limits (``joint_passes``)."""
    from jaxexo.swing import time_law as tl

    rows, cap = joint_passes(dq, ddq, vmax, amax)
    return tl.topp(rows, ds, cap, **kw)


def joint_xmax(dq, ddq, vmax, amax):
    """The passes' largest s'^2 (B, K) for joint limits (time_law.max_speed_curve, the caps)."""
    from jaxexo.swing import time_law as tl

    rows, cap = joint_passes(dq, ddq, vmax, amax)
    return np.minimum(tl.max_speed_curve(rows), cap)


def test_topp_passes_row_by_row_equal_the_batched_passes_and_the_plain_recurrence():
    """The TOPP passes run as Python floats for small batches and vectorised for large ones
    (jaxexo.swing.time_law._min_affine_scan): both must give the same law bit for bit, and both
    must equal the passes written out plainly from the admissible-s'' interval (eq. of the module
    docstring: reach[i-1] = clip(reach[i] - 2 ds L_i(reach[i])), x[i+1] = clip(x[i] + 2 ds U_i(x[i])))."""
    from jaxexo.swing import time_law as tl

    rng = np.random.default_rng(11)
    b, k = tl.SCALAR_ROWS + 6, 160
    dq = rng.normal(size=(b, k, 4))
    dq[:, 40:55, 3] = 0.0  # a joint that stands still for a stretch
    ddq = 5.0 * rng.normal(size=(b, k, 4))
    vmax, amax, ds = (
        np.array([3.0, 4.0, 3.0, 4.0]),
        np.array([15.0, 20.0, 15.0, 20.0]),
        1.0 / (k - 1),
    )
    big, floor_big = _passes(dq, ddq, vmax, amax, ds)
    small = np.concatenate(
        [_passes(dq[i : i + 1], ddq[i : i + 1], vmax, amax, ds)[0] for i in range(b)]
    )
    np.testing.assert_array_equal(big, small)

    # The plain recurrence, one path at a time, with the interval computed per step.
    def interval(i, j, speed):
        """The admissible s'' interval (lo, hi) of path i at step j at s'^2 = speed (every joint's
        acceleration within its limit; the whole line when no joint moves)."""
        moving = np.abs(dq[i, j]) > 1e-12
        if not moving.any():
            return -np.inf, np.inf
        ends = [
            (
                (-amax[m] - ddq[i, j, m] * speed) / dq[i, j, m],
                (amax[m] - ddq[i, j, m] * speed) / dq[i, j, m],
            )
            for m in range(4)
            if moving[m]
        ]
        return max(min(e) for e in ends), min(max(e) for e in ends)

    for i in range(0, b, 7):
        xmax = joint_xmax(dq[i], ddq[i], vmax, amax)[0]
        reach = np.zeros(k)
        for j in range(k - 1, 0, -1):
            lo = interval(i, j, reach[j])[0]
            reach[j - 1] = min(max(reach[j] - 2.0 * ds * lo, 0.0), xmax[j - 1])
        x = np.zeros(k)
        for j in range(k - 1):
            hi = interval(i, j, x[j])[1]
            x[j + 1] = min(max(x[j] + 2.0 * ds * hi, 0.0), reach[j + 1])
        np.testing.assert_allclose(big[i], x, rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(floor_big)) and np.all(big >= 0)


def test_the_row_scan_jumping_along_its_bound_equals_the_step_by_step_scan():
    """The Python-float scan jumps over runs of steps that land on their bound (a smooth path's
    passes ride the limit curve); it must give, bit for bit, the vectorised scan's values, which
    take every step, on paths where most steps ride the bound and some leave it."""
    from jaxexo.swing import time_law as tl

    rng = np.random.default_rng(5)
    k = 400
    s = np.linspace(0.0, 1.0, k)
    rows = tl.SCALAR_ROWS + 1  # vectorised: every step taken
    dq = np.stack(
        [np.cos(3.0 * s + p)[:, None] * [1.0, 0.6, -0.8, 0.4] for p in rng.uniform(0, 3, rows)]
    )
    ddq = np.gradient(dq, s, axis=1)
    dq[:, 150:160, 1] = 0.0  # a joint standing still for a stretch
    vmax, amax, ds = (
        np.array([3.0, 4.0, 3.0, 4.0]),
        np.array([15.0, 20.0, 15.0, 20.0]),
        1.0 / (k - 1),
    )
    limit_rows, cap = joint_passes(dq, ddq, vmax, amax)
    xmax = np.minimum(tl.max_speed_curve(limit_rows), cap)
    fa, fb, ba, bb = tl._affine_steps(tl._lines(limit_rows), ds)
    backward, forward = list(range(k - 1, -1, -1)), list(range(k))
    reach = tl._min_affine_scan(ba, bb, xmax, backward)
    x = tl._min_affine_scan(fa, fb, reach, forward)
    for r in range(rows):
        np.testing.assert_array_equal(tl._scan_floats(ba[r], bb[r], xmax[r], backward), reach[r])
        np.testing.assert_array_equal(tl._scan_floats(fa[r], fb[r], reach[r], forward), x[r])
    # The jump is exercised: most forward steps ride their bound, and some do not.
    on = x[:, 1:] == reach[:, 1:]
    assert 0.5 < on.mean() < 1.0
