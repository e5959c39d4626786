"""The timed swing as a curve (jaxexo.swing.curve, jaxexo.swing.timing): continuous joint
acceleration and bounded jerk on thousands of swings of both generators, the limits held on the
curve at 20 kHz and by finite differences of the samples at 100 Hz to 1 kHz, the chain rule
against finite differences of the curve's own positions, and the exports (piecewise form evaluated
independently, ROS 2 JointTrajectory layout)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.config import scalar_params
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics.scenarios import batch_options
from jaxexo.swing.curve import JointPath
from jaxexo.swing.limits import DeviceLimits
from jaxexo.swing.timing import _joint_paths, time_swings

from benchlib.scenes import safety_sets
from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"


@pytest.fixture(scope="module")
def swings():
    """RL alone and CFFTG on the three benchmark sets (thesis five shifted, unseen shapes, held-out
    families), 400 scenes each: the safe swings of each generator."""
    rl = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(rl.config)
    out = {"rl": [], "cfftg": []}
    for scenes in safety_sets(rl.config, 400).values():
        obs = [s.obstacle for s in scenes]
        kw = batch_options(scenes)
        out["rl"] += [t for t in rl.generate_batch(obs, fallback=None, **kw) if t.ok]
        out["cfftg"] += [t for t in cf.generate_batch(obs, **kw) if t.ok]
    return rl.config, out


def _paths(trajs, config) -> list[JointPath]:
    """The joint paths the timing builds: through the few of the trajectory's joints, refined where
    a leg straightens, that the geometry needs (timing._joint_paths, jaxexo.swing.knots)."""
    return [p.path for p in _joint_paths(trajs, scalar_params(config))]


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_joint_paths_are_c2_with_bounded_third_derivative(swings, method):
    """On every safe swing (over a thousand per generator): q and q' and q'' agree across every
    knot (evaluated just left and right of it, so a jump in q'' would show), and q''' is a finite
    constant per piece."""
    config, trajs = swings
    paths = _paths(trajs[method], config)
    assert len(paths) > 1000
    worst = [0.0, 0.0, 0.0]
    for p in paths:
        k = p.knots[1:-1]
        eps = 1e-9
        left, right = p.derivatives(k - eps, 3), p.derivatives(k + eps, 3)
        scale = [np.abs(d).max() for d in p.derivatives(np.linspace(0, 1, 2001), 2)]
        for o in range(3):
            # a continuous derivative changes by at most (next derivative) * 2 eps across a knot
            jump = np.abs(left[o] - right[o]).max() / scale[o]
            worst[o] = max(worst[o], jump)
        assert np.all(np.isfinite(p.coef[:, 3]))
    assert max(worst) < 1e-5, worst


def _check_on_curve(sw, planned: DeviceLimits, rate_hz: float = 20_000.0):
    t = np.append(np.arange(0.0, sw.duration, 1.0 / rate_hz), sw.duration)
    st = sw.at(t)
    for value, limit in (
        (st.joint_velocity, planned.velocity),
        (st.joint_acceleration, planned.acceleration),
        (st.joint_jerk, planned.jerk),
    ):
        assert np.all(np.abs(value) <= np.asarray(limit)), (np.abs(value).max(0), limit)
    # Independent of the chain rule: finite differences of the curve's own positions at 20 kHz are
    # averages of its derivatives, so they are within the limits too.
    q = st.joint_angles
    dt = 1.0 / rate_hz
    for n, limit in ((1, planned.velocity), (2, planned.acceleration), (3, planned.jerk)):
        fd = np.diff(q, n=n, axis=0) / dt**n
        assert np.all(np.abs(fd) <= np.asarray(limit) * (1 + 1e-6)), n
    # At rest at both ends.
    for end in (0, -1):
        assert np.all(st.joint_velocity[end] == 0) and np.all(st.joint_acceleration[end] == 0)


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_limits_hold_on_the_curve_and_at_every_rate(swings, method):
    """150 swings per generator: the curve within the planned limits at 20 kHz (values and finite
    differences), the samples at 100, 500 and 1000 Hz within them by finite differences, the same
    curve at every rate (its duration changes by less than one period), and the safe verdicts
    kept."""
    config, trajs = swings
    rng = np.random.default_rng(0)
    pick = [trajs[method][i] for i in rng.choice(len(trajs[method]), 150, replace=False)]
    planned = DeviceLimits.from_config(config).planned()
    by_rate = {r: time_swings(pick, config, rate=r) for r in (100.0, 500.0, 1000.0)}
    for sw in by_rate[1000.0]:
        assert sw.ok, sw.reasons
        _check_on_curve(sw, planned)
    for rate, timed in by_rate.items():
        for sw in timed:
            assert sw.within_limits
            q = sw.joint_angles
            for n, limit in ((1, planned.velocity), (2, planned.acceleration), (3, planned.jerk)):
                fd = np.diff(q, n=n, axis=0) * rate**n
                assert np.all(np.abs(fd) <= np.asarray(limit) * (1 + 1e-6)), (rate, n)
    d100 = np.array([s.duration for s in by_rate[100.0]])
    d1k = np.array([s.duration for s in by_rate[1000.0]])
    assert np.all(d1k <= d100 + 1e-9) and np.all(d100 - d1k < 0.01 + 1e-9)


def test_chain_rule_against_finite_differences(swings):
    config, trajs = swings
    (sw,) = time_swings([trajs["rl"][3]], config, rate=100.0)
    h = 1e-5
    t = np.linspace(0.05, sw.duration - 0.05, 50)
    st, lo, hi = sw.at(t), sw.at(t - h), sw.at(t + h)
    np.testing.assert_allclose(
        st.joint_velocity, (hi.joint_angles - lo.joint_angles) / (2 * h), atol=1e-4
    )
    np.testing.assert_allclose(
        st.joint_acceleration, (hi.joint_velocity - lo.joint_velocity) / (2 * h), atol=1e-2
    )
    np.testing.assert_allclose(st.heel_velocity, (hi.heel - lo.heel) / (2 * h), atol=1e-5)
    np.testing.assert_allclose(
        st.heel_acceleration, (hi.heel_velocity - lo.heel_velocity) / (2 * h), atol=1e-3
    )
    np.testing.assert_allclose(st.toe - st.heel, [[config.kinematics.foot_length, 0.0]] * 50)


def test_exports_piecewise_form_and_joint_trajectory(swings, tmp_path):
    """The JSON's piecewise form, evaluated here with plain Horner steps, gives the curve's joint
    angles; the ROS 2 layout has one point per sample with positions, velocities, accelerations
    and time_from_start; sample(rate) is the same curve at another rate."""
    config, trajs = swings
    (sw,) = time_swings([trajs["cfftg"][0]], config, rate=100.0)
    doc = json.loads(sw.to_json(tmp_path / "swing.json"))
    pw = doc["piecewise"]
    tb = np.array(pw["time_law"]["breakpoints_s"])
    tc = np.array(pw["time_law"]["coefficients"])
    sb = np.array(pw["joint_path"]["breakpoints"])
    qc = np.array(pw["joint_path"]["coefficients"])  # (J, P, 4)
    t = np.linspace(0.0, sw.duration, 333)
    i = np.clip(np.searchsorted(tb, t, side="right") - 1, 0, len(tc) - 1)
    d = t - tb[i]
    s = tc[i, 0] + d * (tc[i, 1] + d * (tc[i, 2] + d * tc[i, 3]))
    k = np.clip(np.searchsorted(sb, s, side="right") - 1, 0, qc.shape[1] - 1)
    e = s - sb[k]
    q = np.stack([c[k, 0] + e * (c[k, 1] + e * (c[k, 2] + e * c[k, 3])) for c in qc], axis=1)
    np.testing.assert_allclose(q, sw.at(t).joint_angles, atol=1e-9)
    ros = json.loads(sw.to_joint_trajectory(tmp_path / "swing_ros.json"))
    assert ros["joint_names"] == ["hip_swing", "knee_swing", "hip_stance", "knee_stance"]
    assert len(ros["points"]) == len(sw.time)
    p5 = ros["points"][5]
    assert p5["time_from_start"] == {"sec": 0, "nanosec": 50_000_000}
    np.testing.assert_allclose(p5["accelerations"], sw.joint_acceleration[5])
    fast = sw.sample(1000.0)
    assert (
        fast.rate == 1000.0 and fast.duration == sw.duration and len(fast.time) > 9 * len(sw.time)
    )
    np.testing.assert_allclose(fast.joint_angles[::10], sw.joint_angles[: len(fast.time[::10])])
    with pytest.raises(ValueError, match="rate: control rate must be between"):
        sw.sample(5.0)
    with pytest.raises(ValueError, match="t: expected finite times"):
        sw.at([0.1, float("nan")])


def test_a_batch_times_each_swing_as_it_is_timed_alone(swings):
    """time_swings of a batch (both generators mixed) gives every swing bit for bit what
    time_swing gives it alone, its verdict included: the stacked evaluation only finds pieces, the
    arithmetic is each curve's own."""
    config, trajs = swings
    batch = trajs["rl"][:7] + trajs["cfftg"][:7]
    together = time_swings(batch, config, rate=250.0)
    for t, sw in zip(batch, together):
        (alone,) = time_swings([t], config, rate=250.0)
        assert alone.duration == sw.duration
        np.testing.assert_array_equal(alone.joint_angles, sw.joint_angles)
        np.testing.assert_array_equal(alone.joint_jerk, sw.joint_jerk)
        np.testing.assert_array_equal(alone.peak_jerk, sw.peak_jerk)
        assert alone.checks == sw.checks  # the verdict too (its polyline padded in the batch)


def test_one_curve_evaluates_as_in_a_batch_bit_for_bit(swings):
    """curves_at of one curve (its own scalar path, no offsets or splits) gives every field of the
    state bit for bit what the same curve gives in a batch of several, and without the heel's jerk
    the same other fields; laws_at of one law what it gives among several. Times: the samples, a
    dense grid with both ends, and times before and after the swing."""
    from dataclasses import fields

    from jaxexo.swing.curve import curves_at, laws_at

    config, trajs = swings
    curves = [sw.curve for sw in time_swings(trajs["rl"][:4] + trajs["cfftg"][:4], config)]
    times = [
        np.concatenate([[-0.1, 0.0], np.linspace(0.0, c.duration, 997), [c.duration + 0.2]])
        for c in curves
    ]
    together = curves_at(curves, times)
    laws = laws_at([c.law for c in curves], times)
    for c, t, st, law in zip(curves, times, together, laws):
        (alone,) = curves_at([c], [t])
        (lean,) = curves_at([c], [t], heel_jerk=False)
        assert lean.heel_jerk is None
        for f in fields(st):
            np.testing.assert_array_equal(getattr(alone, f.name), getattr(st, f.name), f.name)
            if f.name != "heel_jerk":
                np.testing.assert_array_equal(getattr(lean, f.name), getattr(st, f.name), f.name)
        for x, y in zip(laws_at([c.law], [t])[0], law):
            np.testing.assert_array_equal(x, y)
        assert alone.path_parameter[0] == 0.0 and alone.path_parameter[-1] == 1.0


def test_cli_writes_the_ros_layout_and_refuses_it_untimed(tmp_path):
    from conftest import run_cli

    ros = tmp_path / "swing_ros.json"
    base = ("generate", "--policy", str(POLICY), "--method", "cfftg", "--obstacle", "base1")
    r = run_cli(*base, "--out", str(tmp_path / "a.csv"), "--ros", str(ros))
    assert r.returncode == 2 and "--ros" in r.stderr and "Traceback" not in r.stderr
    assert not ros.exists() and not (tmp_path / "a.csv").exists()
    r = run_cli(*base, "--rate", "500", "--out", str(tmp_path / "b.csv"), "--ros", str(ros))
    assert r.returncode == 0, r.stderr
    doc = json.loads(ros.read_text())
    t = [
        p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in doc["points"]
    ]
    np.testing.assert_allclose(np.diff(t), 1 / 500, atol=1e-9)
    assert (
        doc["points"][0]["velocities"] == [0.0] * 4
        and doc["points"][-1]["accelerations"] == [0.0] * 4
    )


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_the_guaranteed_clearance_holds_on_the_curve_sampled_densely(swings, method):
    """Independent of the verdict's polyline and bound: the exact foot clearance at 20,000 poses of
    the timed curve (jaxexo.physics.geometry, pose by pose) is never below the clearance the
    verdict guarantees, on 60 swings per generator."""
    from jaxexo.physics import geometry

    config, trajs = swings
    rng = np.random.default_rng(1)
    pick = [trajs[method][i] for i in rng.choice(len(trajs[method]), 60, replace=False)]
    for sw in time_swings(pick, config, rate=100.0):
        st = sw.at(np.linspace(0.0, sw.duration, 20_001))
        c = geometry.foot_clearance(np, st.heel, config.kinematics.foot_length, sw.scene.outline)
        assert c.min() >= sw.checks.min_clearance, (c.min(), sw.checks.min_clearance)
        assert st.heel[:, 1].min() >= -1e-12  # above the floor, to the kinematics' rounding


def _foot_clearance_brute(heel, foot, outline):
    """Independent of jaxexo.physics: the flat foot [heel, heel + (foot, 0)] (n, 2) against the
    outline polyline, edge by edge: the least of the four end-to-segment distances, 0 where the
    foot crosses an edge; negative where the heel lies under the outline (the closed polygon's
    crossing number)."""

    def to_segment(p, a, b):  # p (n, 2), a and b (2,) or (n, 2)
        ab = b - a
        t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0.0, 1.0)
        return np.linalg.norm(p - a - t[:, None] * ab, axis=-1)

    def side(a, b, p):
        return (b[..., 0] - a[..., 0]) * (p[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
            p[..., 0] - a[..., 0]
        )

    toe = heel + np.array([foot, 0.0])
    best = np.full(len(heel), np.inf)
    for a, b in zip(outline[:-1], outline[1:]):
        d = np.minimum(to_segment(heel, a, b), to_segment(toe, a, b))
        d = np.minimum(
            d, np.minimum(to_segment(a[None], heel, toe), to_segment(b[None], heel, toe))
        )
        cross = (side(a, b, heel) * side(a, b, toe) < 0) & (
            side(heel, toe, a) * side(heel, toe, b) < 0
        )
        best = np.minimum(best, np.where(cross, 0.0, d))
    closed = np.vstack([outline, outline[:1]])
    under = np.zeros(len(heel), bool)
    for a, b in zip(closed[:-1], closed[1:]):
        if a[1] != b[1]:
            y = a[0] + (heel[:, 1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            under ^= ((a[1] > heel[:, 1]) != (b[1] > heel[:, 1])) & (heel[:, 0] < y)
    return np.where(under, -best, best)


def _dense_clearance(sw, foot):
    """The least foot clearance (``_foot_clearance_brute``) over the timed curve: every 200 us,
    then every 10 us (100 kHz) within 200 us of each 200-us sample that may hold the least (the
    clearance changes no faster than the heel moves: within the largest heel speed x 200 us)."""
    dt = 2e-4
    t = np.append(np.arange(0.0, sw.duration, dt), sw.duration)
    st = sw.at(t)
    c = _foot_clearance_brute(st.heel, foot, sw.scene.outline)
    near = np.round(t[c <= c.min() + np.linalg.norm(st.heel_velocity, axis=1).max() * dt] / 1e-5)
    fine = np.unique(np.clip((near[:, None] + np.arange(-20, 21)).ravel() * 1e-5, 0, sw.duration))
    return min(c.min(), _foot_clearance_brute(sw.at(fine).heel, foot, sw.scene.outline).min())


def _tie_shift(traj, config, c0: float, margin: float, k: int) -> float:
    """How much to grow the swing's obstacle (``_grown``, at most by 30 %) for the verdict's
    clearance to be 1e-5 m above the margin (k odd) or below it (k even): secant steps."""
    want = margin + (1e-5 if k % 2 else -1e-5)
    a, ca, b = 0.0, c0, 0.01
    for _ in range(6):
        cb = time_swings([_grown(traj, b)], config, rate=100.0)[0].checks.min_clearance
        if abs(cb - want) < 5e-6 or cb == ca:
            return b
        a, ca, b = b, cb, float(np.clip(b + (want - cb) * (b - a) / (cb - ca), -0.3, 0.3))
    return b


def _grown(traj, k: float):
    """The swing with its obstacle scaled by 1 + k about the middle of its base (the verdict's
    scene; the obstacle stays on the ground)."""
    import dataclasses

    o = traj.scene.outline
    base = np.array([0.5 * (o[:, 0].min() + o[:, 0].max()), 0.0])
    scene = traj.scene._replace(outline=base + (1.0 + k) * (o - base))
    return dataclasses.replace(traj, scene=scene)


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_no_swing_is_ok_where_a_dense_look_finds_the_foot_closer_than_the_margin(swings, method):
    """The timed verdict against an independent look at the curve (the foot's distance to the
    outline by brute force, ``_dense_clearance``: 5 kHz, 1 MHz near the closest): the clearance
    it guarantees is never above what the dense look finds, on 80 swings per generator (the 50
    closest to the margin among them) and on 30 near-ties made by growing each obstacle until the
    verdict's clearance is within 2e-5 m of env.min_clearance, either side. So no swing is ok
    with the foot closer than the margin anywhere on its curve."""
    config, trajs = swings
    foot, margin = config.kinematics.foot_length, config.env.min_clearance
    pool = sorted(trajs[method], key=lambda t: t.checks.min_clearance)
    rng = np.random.default_rng(2)
    pick = pool[:50] + [pool[i] for i in rng.choice(np.arange(50, len(pool)), 30, replace=False)]
    timed = time_swings(pick, config, rate=100.0)
    ties = []
    for k, (t, sw) in enumerate(zip(pick, timed)):
        assert _dense_clearance(sw, foot) >= sw.checks.min_clearance, k
        if k < 30:  # a near-tie: the obstacle grown by the secant on the verdict's clearance
            ties.append(_grown(t, _tie_shift(t, config, sw.checks.min_clearance, margin, k)))
    near = ok = 0
    for sw in time_swings(ties, config, rate=100.0):
        dense = _dense_clearance(sw, foot)
        assert dense >= sw.checks.min_clearance
        assert not sw.checks.clearance_ok or dense >= margin
        if abs(sw.checks.min_clearance - margin) < 2e-5:
            near += 1
            ok += int(sw.checks.clearance_ok)
    # Most searches end within 2e-5 m of the margin, on both sides of it.
    assert near >= 24 and min(ok, near - ok) >= 10, (near, ok)


def test_the_check_polyline_strays_at_most_its_tolerance_from_the_heel_curve(swings):
    """curve.check_points' polyline (every knot, spaced by the per-piece bound on |heel''|) against
    the heel curve evaluated at 16 points inside every chord, on 300 swings of both generators:
    never farther than CURVE_TOL from its chord; and not over-resolved (most chords need most of
    their tolerance's square root: the points are not ten times too dense)."""
    from jaxexo.swing.curve import check_points, heel_derivatives
    from jaxexo.swing.timing import CURVE_TOL

    config, trajs = swings
    sp = scalar_params(config)
    lengths = (sp.thigh, sp.shin)
    worst, used = 0.0, []
    for p in _paths(trajs["rl"][:150] + trajs["cfftg"][:150], config):
        s, q, heel = check_points(lengths, 0.3, p, CURVE_TOL)
        assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) > 0)
        assert np.isin(p.knots, s).all()
        u = np.linspace(0.0, 1.0, 18)[1:-1]
        inner = (s[:-1, None] + u * np.diff(s)[:, None]).ravel()
        h = heel_derivatives(lengths, 0.3, p.derivatives(inner, 0))[0].reshape(-1, 16, 2)
        a, b = heel[:-1, None], heel[1:, None]
        ab = b - a
        t = np.clip(((h - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0.0, 1.0)
        dev = np.linalg.norm(h - a - t[..., None] * ab, axis=-1).max(axis=1)
        worst = max(worst, dev.max())
        used.append(np.median(dev) / CURVE_TOL)
    assert worst <= CURVE_TOL, worst
    assert np.median(used) > 1e-3, np.median(used)
