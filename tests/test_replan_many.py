"""Replans of both generators over surprise scenes (benchlib.replan_bench: shapes never
trained on, planned over an estimate, replanned mid-swing over the true obstacle), each held to
checks independent of the replan: the swing before the switch equals the old one, the joints are
C2 across it (both sides evaluated apart, against the proven jerk), the samples' finite
differences at 1 kHz stay within the proven peaks and, for a swing within the limits, within the
planned limits; and every swing flagged ok is found clear of the true obstacle by the margin by a
dense look at 5 kHz (segment distances written in the benchmark, not jaxexo.physics), above the
ground and at rest on the floor within 5 cm of the goal. JAXEXO_REPLAN_SCALE=k multiplies the
scenes (the CI run replans about 165 swings; a run at scale 10, 1,658, is quoted in
docs/replanning.md)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.inference import TrajectoryGenerator
from jaxexo.swing.timing import time_swing

from benchlib.replan_bench import C2_EPS, dense_clearance, judge, surprise_scenes
from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
SCALE = int(os.environ.get("JAXEXO_REPLAN_SCALE", "1"))
SCENES = 100 * SCALE  # per generator
SEED = 4_242


@pytest.fixture(scope="module")
def replans():
    """(old, new, at, true outline, goal) of every scene whose swing over the estimate is ok and
    whose replan is not refused, for the RL generator (fallback off) and CFFTG."""
    rl = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(rl.config)
    out = {"rl": [], "cfftg": []}
    for s in surprise_scenes(rl.config, SCENES, SEED):
        kw = {"pivot": s.pivot, "start_y": s.start_y, "step_length": s.step_length}
        for name, gen, opts in (("rl", rl, {"fallback": None}), ("cfftg", cf, {})):
            try:
                old = time_swing(gen.generate(s.estimate, **opts, **kw), rl.config)
            except ValueError:  # the estimate's placement is not a valid scene
                continue
            if not old.ok:
                continue
            at = s.at_fraction * old.duration
            try:
                new = gen.replan(old, s.true, at=at, **opts)
            except ValueError as e:  # the foot already within the margin of the true obstacle
                assert "obstacle:" in str(e) or "at:" in str(e)
                continue
            out[name].append((old, new, at, np.asarray(s.true.outline), old.scene.goal_y))
    return rl, out


@pytest.mark.parametrize("name", ["rl", "cfftg"])
def test_replans_join_c2_and_keep_their_proven_peaks(replans, name):
    rl, out = replans
    cases = out[name]
    assert len(cases) >= SCENES // 3
    for old, new, at, _, _ in cases:
        assert new.switch_times == old.switch_times + (at,)
        before = np.linspace(0.0, at, 200)
        assert np.abs(new.at(before).joint_angles - old.at(before).joint_angles).max() <= 1e-12
        a, b = old.at(np.array([at - C2_EPS])), new.at(np.array([at + C2_EPS]))
        jerk = max(float(np.max(old.peak_jerk)), float(np.max(new.peak_jerk)))
        acc = max(float(np.max(old.peak_acceleration)), float(np.max(new.peak_acceleration)))
        d = 2.0 * C2_EPS
        assert np.abs(b.joint_velocity - a.joint_velocity).max() <= acc * d * 1.01 + 1e-9
        assert np.abs(b.joint_acceleration - a.joint_acceleration).max() <= jerk * d * 1.01 + 1e-7
        q = np.asarray(new.sample(1000.0).joint_angles)
        v, acc_fd = np.diff(q, axis=0) * 1e3, np.diff(q, n=2, axis=0) * 1e6
        assert np.all(np.abs(v).max(axis=0) <= new.peak_velocity * (1 + 1e-6) + 1e-9)
        assert np.all(np.abs(acc_fd).max(axis=0) <= new.peak_acceleration * (1 + 1e-6) + 1e-6)
        if new.within_limits:
            lim = new.limits.planned()
            assert np.all(new.peak_velocity <= lim.velocity)
            assert np.all(new.peak_acceleration <= lim.acceleration)
            assert np.all(new.peak_jerk <= lim.jerk)


@pytest.mark.parametrize("name", ["rl", "cfftg"])
def test_a_replan_flagged_ok_is_safe_by_a_dense_look(replans, name):
    rl, out = replans
    margin = float(rl.config.env.min_clearance)
    foot = float(rl.config.kinematics.foot_length)
    flagged = 0
    for old, new, at, outline, goal in out[name]:
        if not new.ok:
            assert new.reasons
            continue
        flagged += 1
        j = judge(old, new, at, outline, goal, foot)
        # every dense sample is a point of the curve, which the verdict keeps clear by the margin
        assert j.clearance >= margin - 1e-9, (j.clearance, new.checks.min_clearance)
        assert j.lowest >= -1e-9 and j.landing_error <= 0.05 and j.landing_speed < 1e-6
        assert max(j.limit_ratio) <= 1.0 + 1e-9
        # the whole swing, before the switch too, against the true obstacle
        whole = new.at(np.linspace(0.0, new.duration, 4000)).heel
        assert dense_clearance(whole, foot, outline).min() >= margin - 1e-9
    assert flagged >= len(out[name]) // 2
