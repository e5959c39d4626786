"""A swing replanned in flight, driven in MuJoCo through its switch (jaxexo.sim.driven's
``before``): the reference is the old swing's until the switch and the new one's after (a sampled
reference joined C2 from the drive's own state); the commanded acceleration steps no more across
the switch than anywhere else, where joins of unrelated swings (C0: positions apart; C1:
positions and velocities matched, accelerations not) jump by tens of times more; the true
obstacle's scene is the replay's from the start; bad ``before`` refused naming it."""

from __future__ import annotations

import dataclasses
import types

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics.geometry import Obstacle
from jaxexo.swing import replan
from jaxexo.swing.timing import time_swing

from conftest import ROOT, lifted_continuation

mujoco = pytest.importorskip("mujoco")

from jaxexo.sim.driven import (  # noqa: E402
    SWITCH_EPS,
    _simulate,
    commanded_acceleration,
    reference_jumps,
    switch_figures,
)
from jaxexo.sim.replay import Legs, SimError, driven_replay, reference_states  # noqa: E402

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
FRAC = 0.2  # the switch, as a fraction of the old swing


continuation = lifted_continuation


def taller_scene(gen, swing, obstacle):
    """``obstacle``'s scene with the swing's pivot, start and goal (the true scene of a replan)."""
    sc = swing.scene
    s = gen.scene(
        obstacle, pivot_y=sc.pivot_y, start_y=sc.start_y, step_length=sc.goal_y - sc.start_y
    )
    return s._replace(goal_y=sc.goal_y, pivot_kind=sc.pivot_kind)


@pytest.fixture(scope="module")
def pairs():
    """(old, replanned) by the policy and by CFFTG over a 6 cm block, replanned at FRAC of the
    swing over the true, 9 cm block (a 4 cm lift), and an unrelated swing (over a pole)."""
    gen = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(gen.config)
    est, true = Obstacle.rectangle(0.10, 0.06), Obstacle.rectangle(0.10, 0.09)
    out = {}
    for name, make in (
        ("rl", lambda o: gen.generate(o, fallback=None)),
        ("cfftg", lambda o: cf.generate(o)),
    ):
        old = time_swing(make(est), gen.config)
        at = FRAC * old.duration
        cont = continuation(gen, old, at, 0.04, taller_scene(gen, old, true))
        new = replan.continue_swing(old, cont, at=at, sp=gen.sp)
        other = time_swing(make(Obstacle.rectangle(0.03, 0.16)), gen.config)
        out[name] = (old, new, other)
    return gen, out


class Affine:
    """An unrelated swing joined C1 to another at the switch ``at``: from ``at`` it runs from its
    own instant of the largest acceleration mismatch with the other's at ``at``, moved by
    a + b (t - at) so that its position and velocity at ``at`` are the other's."""

    def __init__(self, swing, old, at: float):
        self._swing, self.switch_times, self._at = swing, (at,), at
        a = old.at(np.array([at]))
        grid = swing.at(np.linspace(0.0, swing.duration, 400))
        k = int(np.argmax(np.abs(grid.joint_acceleration - a.joint_acceleration).max(axis=1)))
        self._t = float(grid.time[k])
        self._p = a.joint_angles[0] - grid.joint_angles[k]
        self._v = a.joint_velocity[0] - grid.joint_velocity[k]

    def __getattr__(self, name):
        return getattr(self._swing, name)

    def at(self, t):
        dt = np.asarray(t) - self._at
        st = self._swing.at(self._t + dt)
        return types.SimpleNamespace(
            joint_angles=st.joint_angles + self._p + self._v * dt[:, None],
            joint_velocity=st.joint_velocity + self._v,
            joint_acceleration=st.joint_acceleration,
        )


@pytest.mark.parametrize("name", ["rl", "cfftg"])
def test_the_reference_is_the_old_swing_before_the_switch_and_the_new_after(pairs, name):
    gen, sw = pairs
    old, new, other = sw[name]
    at = new.switch_times[-1]
    run = _simulate(new, Legs(gen.config, new.scene), new.limits, 0.05, "pd_ff", before=old)
    t = np.arange(run.steps + 2) * run.dt
    pre, post = t < at, t >= at
    np.testing.assert_array_equal(run.reference[pre], old.at(t[pre]).joint_angles)
    np.testing.assert_array_equal(run.reference[post], new.at(t[post]).joint_angles)
    # Unrelated swings: the first's before the switch, the second's after (they differ there).
    fake = dataclasses.replace(other, switch_times=(at,))
    q = reference_states(fake, t, before=old)[0]
    np.testing.assert_array_equal(q[pre], old.at(t[pre]).joint_angles)
    np.testing.assert_array_equal(q[post], other.at(t[post]).joint_angles)
    assert np.abs(other.at(t[pre]).joint_angles - q[pre]).max() > 1e-3


@pytest.mark.parametrize("kind,rate", [("quintic", None), ("quintic", 500.0), ("cubic", 1000.0)])
def test_a_sampled_reference_leaves_the_old_samples_from_the_drives_own_state(pairs, kind, rate):
    """Before the switch the old swing's samples interpolated; from the switch one piece from the
    old reference's state there (position and velocity; the acceleration too for the quintic) to
    the first new sample at least half a period later; then the new samples interpolated."""
    _, sw = pairs
    old, new, _ = sw["rl"]
    at = new.switch_times[-1]
    period = 1.0 / (new.rate if rate is None else rate)
    t = np.arange(0.0, new.duration + 0.05, 1e-4)
    q, v, a = reference_states(new, t, kind, rate, before=old)
    k = int(np.ceil(at / period + 0.5 - 1e-9))
    pre, post = t < at, t >= k * period
    for got, want in zip((q, v, a), reference_states(old, t[pre], kind, rate)):
        np.testing.assert_array_equal(got[pre], want)
    for got, want in zip((q, v, a), reference_states(new, t[post], kind, rate)):
        np.testing.assert_array_equal(got[post], want)
    assert 0.5 * period <= k * period - at < 1.5 * period
    left = reference_states(old, np.array([at]), kind, rate)
    right = reference_states(new, np.array([at, k * period]), kind, rate, before=old)
    np.testing.assert_allclose(right[0][0], left[0][0], atol=1e-12)
    np.testing.assert_allclose(right[1][0], left[1][0], atol=1e-9)
    if kind == "quintic":
        np.testing.assert_allclose(right[2][0], left[2][0], atol=1e-6)
    sample = new.sample(1.0 / period)
    np.testing.assert_allclose(right[0][1], sample.joint_angles[k], atol=1e-12)
    # The old samples after the switch differ from the new ones: the join is not a no-op.
    assert (
        np.abs(old.sample(1.0 / period).joint_angles[k + 3] - sample.joint_angles[k + 3]).max() > 0
    )


@pytest.mark.parametrize("name", ["rl", "cfftg"])
@pytest.mark.parametrize("kind,rate", [("curve", None), ("quintic", None)])
def test_the_commanded_acceleration_does_not_jump_at_the_switch(pairs, name, kind, rate):
    gen, sw = pairs
    old, new, other = sw[name]
    at = new.switch_times[-1]
    legs = Legs(gen.config, new.scene)
    run = _simulate(new, legs, new.limits, 0.05, "pd_ff", kind, rate, before=old)
    assert not run.clip_a.any() and not run.clip_v.any()
    good = switch_figures(run, at, reference_jumps(new, old, kind, rate))
    assert good.switch_time_s == at
    # No jump (a C2 join: each side's position, velocity and acceleration meet, to the next
    # derivative's peak over the 2e-7 s between them); the commanded acceleration's steps across
    # the switch no larger than elsewhere, per physics step and per control period.
    peak = lambda k: max(float(np.max(getattr(x, k))) for x in (old, new))  # noqa: E731
    jerk, d = peak("peak_jerk"), 2 * SWITCH_EPS * 1.01
    assert good.position_jump_rad <= peak("peak_velocity") * d + 1e-12
    assert good.velocity_jump_rad_s <= peak("peak_acceleration") * d + 1e-9
    assert good.acceleration_jump_rad_s2 <= jerk * d + 1e-6
    assert good.switch_step_rad_s2 <= good.step_elsewhere_rad_s2
    assert good.period_change_rad_s2 <= good.period_change_elsewhere_rad_s2
    if kind == "curve":
        # Unclipped, the setpoints are the curve at every physics step: their acceleration is the
        # curve's second difference, and a change of it over w steps a mean of the jerk over
        # w + 1 steps, within the swing's proven jerk peak times w steps.
        t = np.arange(run.steps + 1) * run.dt
        q = np.where((t < at)[:, None], old.at(t).joint_angles, new.at(t).joint_angles)
        acc = commanded_acceleration(run)
        np.testing.assert_allclose(acc, np.diff(q, n=2, axis=0) / run.dt**2, atol=1e-5)
        assert good.switch_step_rad_s2 <= jerk * run.dt * (1 + 1e-6) + 1e-6
        assert good.period_change_rad_s2 <= jerk * run.sub * run.dt * (1 + 1e-6) + 1e-6
    # Negative controls, from two unrelated swings: joined C0 (positions apart: the setpoints
    # clip, catching up at the limit) and C1 (positions and velocities matched, accelerations
    # not: nothing clips, the jump is the accelerations' mismatch and the commanded
    # acceleration's step across the switch stands out). Both far above any ordinary step.
    c0 = dataclasses.replace(other, switch_times=(at,))
    r = _simulate(c0, legs, new.limits, 0.05, "pd_ff", before=old)
    b = switch_figures(r, at, reference_jumps(c0, old))
    assert r.clip_a.any() and b.position_jump_rad > 1e-3
    assert b.switch_step_rad_s2 > 10.0 * good.step_elsewhere_rad_s2
    c1 = Affine(other, old, at)
    r = _simulate(c1, legs, new.limits, 0.05, "pd_ff", before=old)
    b = switch_figures(r, at, reference_jumps(c1, old))
    assert not r.clip_a.any() and b.step_ratio > 10.0
    assert b.position_jump_rad < 1e-5 and b.velocity_jump_rad_s < 1e-4
    mismatch = np.abs(
        c1.at(np.array([at])).joint_acceleration - old.at(np.array([at])).joint_acceleration
    )
    assert b.acceleration_jump_rad_s2 == pytest.approx(float(mismatch.max()), rel=1e-3)
    assert b.acceleration_jump_rad_s2 > 10.0 * good.step_elsewhere_rad_s2
    assert b.period_change_rad_s2 > 3.0 * good.period_change_elsewhere_rad_s2


@pytest.mark.parametrize("name", ["rl", "cfftg"])
def test_a_replanned_swing_driven_through_the_switch_clears_the_true_obstacle(pairs, name):
    gen, sw = pairs
    old, new, _ = sw[name]
    assert new.ok and new.scene.obstacle.height == pytest.approx(0.09)
    d = driven_replay(new, gen.config, settle=0.05, before=old)
    f = d.figures
    assert f.margin_kept and not f.contact and not f.saturated
    assert f.heel_error_p95_m < 0.0025
    assert d.switch is not None and d.switch.acceleration_jump_rad_s2 < 1e-3
    assert d.switch.step_ratio <= 1.0 and d.switch.period_ratio <= 1.0
    js = d.to_dict()
    assert js["switch"]["switch_time_s"] == new.switch_times[-1]
    assert "switch" not in driven_replay(new, gen.config, settle=0.0).to_dict()
    # The replay's scene is the true obstacle's from the start: the old swing, left alone, is
    # measured against it (it passes lower over the taller block than the replanned one).
    left = driven_replay(old, gen.config, legs=Legs(gen.config, new.scene), settle=0.0)
    assert left.figures.mujoco_min_distance_m < f.mujoco_min_distance_m


def test_a_bad_before_is_refused_naming_it(pairs):
    gen, sw = pairs
    old, new, other = sw["rl"]
    for before, timed, match in (
        ("old", new, "before: expected the TimedSwing that was replanned, got str"),
        (old, old, "before: the swing replayed was not replanned"),
        (new, new, r"before: expected the swing replanned at .* got one with switch times \["),
        (
            old,
            dataclasses.replace(new, switch_times=(old.duration + 0.1,)),
            "before: lands at",
        ),
        (dataclasses.replace(old, curve=None), new, "before: the 'curve' reference needs"),
    ):
        with pytest.raises(SimError, match=match):
            driven_replay(timed, gen.config, before=before)


def test_the_benchmarks_surprise_scenes_are_what_they_say():
    from jaxexo.physics.scene import make_scene

    from benchlib import replan_replay_bench as bench

    foot = 0.2
    scenes = bench.surprise_scenes(foot, 48, seed=3)
    assert [s.shape for s in scenes[:8]] == list(bench.SHAPES) * 2
    assert {s.change for s in scenes} == {"taller", "moved"} and len({s.pivot for s in scenes}) == 3
    for s in scenes:
        est, true = np.asarray(s.estimate.outline), np.asarray(s.true.outline)
        assert 0.15 <= s.at_fraction <= 0.40
        if s.change == "taller":
            np.testing.assert_allclose(est[:, 0], true[:, 0])
            assert 1.3 <= s.true.height / s.estimate.height <= 1.6
        else:
            np.testing.assert_allclose(est[:, 1], true[:, 1])
            shift = true[:, 0] - est[:, 0]
            assert np.ptp(shift) < 1e-12 and 0.03 <= abs(shift[0]) <= 0.05
        for ob in (s.estimate, s.true):  # both lie in the gap: make_scene would refuse otherwise
            make_scene(ob, s.pivot, s.start_y, s.step_length, foot_length=foot)
    again = bench.surprise_scenes(foot, 48, seed=3)
    assert all(np.array_equal(a.true.outline, b.true.outline) for a, b in zip(scenes, again))


def test_the_benchmark_replays_a_replanned_swing_through_its_switch(pairs):
    """The benchmark's scene through the public replan of both generators: the old swing over the
    estimate, the replan over the true obstacle at the scene's fraction, both references replayed
    through the switch in the true scene."""
    from benchlib import replan_replay_bench as bench

    gen, _ = pairs
    gens = {"rl": gen, "cfftg": CFFTG(gen.config)}
    scenes = bench.surprise_scenes(gen.config.kinematics.foot_length, 6, seed=1)
    seen = set()
    for i, sc in enumerate(scenes):
        for name, g in gens.items():
            row, drv, pair = bench.replay_scene(i, sc, name, g, gen.config)
            assert row.status in ("ok", "not ok", "refused", "old not ok")
            if row.status != "ok":
                assert not drv and pair is None
                continue
            seen.add(name)
            old, new = pair
            assert new.switch_times == (row.at_s,) and row.at_s == sc.at_fraction * old.duration
            assert new.scene.obstacle is sc.true or np.array_equal(
                new.scene.obstacle.outline, sc.true.outline
            )
            assert set(drv) == {"curve", "quintic"}
            for kind, d in drv.items():
                assert d.reference == kind and d.flagged_ok and d.switch.switch_time_s == row.at_s
                assert not d.figures.contact
                assert row.replays[kind]["switch"] == dataclasses.asdict(d.switch)
        if seen == set(gens):
            break
    assert seen == set(gens)
