"""The join of a replanned swing (jaxexo.swing.replan.continue_swing), independent of any generator:
the continuation here is the old swing's own heel path from the switch, lifted by a smooth bump.
The replanned swing must equal the old one before the switch, be C2 at it (both sides evaluated
apart), keep its proven peaks at 10 kHz by finite differences of its samples, land at rest on the
floor, and allow another replan; the start-conditioned spline is held to its defining conditions
piece by piece. Refusals of bad switch times."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics.geometry import Obstacle
from jaxexo.swing import replan
from jaxexo.swing.timing import time_swing

from conftest import ROOT, lifted_continuation

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"


@pytest.fixture(scope="module")
def swings():
    gen = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(gen.config)
    out = []
    for h, w in ((0.05, 0.1), (0.09, 0.15), (0.12, 0.06)):
        obs = Obstacle.rectangle(width=w, height=h)
        out.append(time_swing(gen.generate(obs, fallback=None), gen.config))
        out.append(time_swing(cf.generate(obs), gen.config))
    return gen, out


lifted = lifted_continuation


CASES = [(i, f, lift) for i in range(6) for f in (0.15, 0.4, 0.6) for lift in (0.0, 0.03)]


@pytest.mark.parametrize("i,frac,lift", CASES)
def test_the_join_is_the_old_swing_before_and_c2_at_the_switch(swings, i, frac, lift):
    gen, sws = swings
    old = sws[i]
    at = frac * old.duration
    new = replan.continue_swing(old, lifted(gen, old, at, lift), at=at, sp=gen.sp)
    assert new.switch_times == (at,)
    before = np.linspace(0.0, at, 400)
    a, b = old.at(before), new.at(before)
    for k in ("joint_angles", "joint_velocity", "joint_acceleration", "heel"):
        assert np.abs(getattr(a, k) - getattr(b, k)).max() <= 1e-12, k
    # Both sides of the switch, each from its own law and path pieces (the old curve left of it).
    for eps in (1e-6, 1e-7):
        left, right = old.at(np.array([at - eps])), new.at(np.array([at + eps]))
        jerk = max(float(np.max(old.peak_jerk)), float(np.max(new.peak_jerk)))
        acc = max(float(np.max(old.peak_acceleration)), float(np.max(new.peak_acceleration)))
        vel = max(float(np.max(old.peak_velocity)), float(np.max(new.peak_velocity)))
        d = 2.0 * eps
        assert np.abs(left.joint_angles - right.joint_angles).max() <= vel * d * 1.01 + 1e-12
        assert np.abs(left.joint_velocity - right.joint_velocity).max() <= acc * d * 1.01 + 1e-9
        assert (
            np.abs(left.joint_acceleration - right.joint_acceleration).max()
            <= jerk * d * 1.01 + 1e-7
        )


@pytest.mark.parametrize("i", range(6))
def test_a_replanned_swing_keeps_its_peaks_and_lands_at_rest(swings, i):
    gen, sws = swings
    old = sws[i]
    at = 0.35 * old.duration
    new = replan.continue_swing(old, lifted(gen, old, at, 0.02), at=at, sp=gen.sp, rate=10_000.0)
    dt = 1.0 / new.rate
    q = new.joint_angles
    v, a = np.diff(q, axis=0) / dt, np.diff(q, n=2, axis=0) / dt**2
    # Finite differences are means of the derivative over a period: within its maxima.
    assert np.all(np.abs(v).max(axis=0) <= new.peak_velocity * (1 + 1e-6))
    assert np.all(np.abs(a).max(axis=0) <= new.peak_acceleration * (1 + 1e-6) + 1e-6)
    if new.within_limits:
        planned = new.limits.planned()
        assert np.all(new.peak_velocity <= planned.velocity)
        assert np.all(new.peak_acceleration <= planned.acceleration)
    end = new.at(np.array([new.duration]))
    assert np.abs(end.joint_velocity).max() < 1e-9 and np.abs(end.joint_acceleration).max() < 1e-6
    assert abs(end.heel[0, 1]) < 1e-9
    assert abs(end.heel[0, 0] - old.at(np.array([old.duration])).heel[0, 0]) < 0.05


def test_a_replanned_swing_can_be_replanned_again(swings):
    gen, sws = swings
    old = sws[1]
    t1, t2 = 0.25 * old.duration, 0.5 * old.duration
    once = replan.continue_swing(old, lifted(gen, old, t1, 0.02), at=t1, sp=gen.sp)
    twice = replan.continue_swing(once, lifted(gen, once, t2, 0.01), at=t2, sp=gen.sp)
    assert twice.switch_times == (t1, t2)
    before = np.linspace(0.0, t2, 300)
    assert np.abs(twice.at(before).joint_angles - once.at(before).joint_angles).max() <= 1e-12
    with pytest.raises(ValueError, match="at: .*after its last switch"):
        replan.checked_switch(twice, 0.9 * t2, gen.config)


def test_the_start_conditioned_spline_meets_its_conditions():
    rng = np.random.default_rng(3)
    knots = np.concatenate([[0.0], np.sort(rng.uniform(0.0, 1.0, 9)), [1.0]])
    values = rng.normal(size=(len(knots), 4))
    dq0, ddq0 = rng.normal(size=4), rng.normal(size=4)
    p = replan.start_conditioned_spline(knots, values, dq0, ddq0)
    c = p.coef  # (P, 4, J)
    h = np.diff(knots)[:, None]
    assert np.array_equal(c[0, 0], values[0])
    assert np.allclose(c[0, 1], dq0, atol=1e-12) and np.allclose(2 * c[0, 2], ddq0, atol=1e-10)
    # Each piece's end against the next piece's start: value, slope, curvature.
    end_q = ((c[:, 3] * h + c[:, 2]) * h + c[:, 1]) * h + c[:, 0]
    end_d = (3 * c[:, 3] * h + 2 * c[:, 2]) * h + c[:, 1]
    end_dd = 6 * c[:, 3] * h + 2 * c[:, 2]
    assert np.allclose(end_q[:-1], c[1:, 0], atol=1e-10)
    assert np.allclose(end_d[:-1], c[1:, 1], atol=1e-8)
    assert np.allclose(end_dd[:-1], 2 * c[1:, 2], atol=1e-6)
    # Through the given values from the third knot on (the second is free), not-a-knot at the end.
    assert np.allclose(np.vstack([c[2:, 0], end_q[-1:]]), values[2:], atol=1e-10)
    assert np.allclose(c[-1, 3], c[-2, 3], atol=1e-6 * np.abs(c[-1, 3]).max())


def test_bad_switch_times_are_refused(swings):
    gen, sws = swings
    sw = sws[0]
    for bad in (0.0, -0.1, sw.duration, sw.duration + 1.0, float("nan")):
        with pytest.raises(ValueError, match="at: expected a time in s within the swing"):
            replan.checked_switch(sw, bad, gen.config)
    with pytest.raises(TypeError, match="at: expected a time in seconds"):
        replan.checked_switch(sw, "0.3", gen.config)
    with pytest.raises(TypeError, match="swing: expected a TimedSwing"):
        replan.checked_switch(gen.generate(Obstacle.rectangle(0.1, 0.05)), 0.3, gen.config)
    late = sw.duration - 1e-3
    with pytest.raises(ValueError, match="too late to replan"):
        replan.continue_swing(sw, lifted(gen, sw, late, 0.0), at=late, sp=gen.sp)
