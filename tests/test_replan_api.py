"""The public replanning (TrajectoryGenerator.replan, CFFTG.replan): a replan of a replan, the
fallback, strict, and the refusals at the boundary, each naming the argument."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.inference import TrajectoryGenerator, time_swing
from jaxexo.physics.geometry import Obstacle
from jaxexo.swing.trajectory import TrajectoryError

from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"


@pytest.fixture(scope="module")
def setup():
    gen = TrajectoryGenerator.load(POLICY)
    swing = time_swing(gen.generate(Obstacle.rectangle(0.10, 0.05)), gen.config, rate=100)
    return gen, CFFTG(gen.config), swing


def test_both_generators_replan_and_a_replan_replans_again(setup):
    gen, cf, swing = setup
    taller = Obstacle.rectangle(0.10, 0.09)
    for g in (gen, cf):
        old = (
            swing
            if g is gen
            else time_swing(cf.generate(Obstacle.rectangle(0.10, 0.05)), gen.config)
        )
        once = g.replan(old, taller, at=0.25)
        assert once.ok and once.switch_times == (0.25,)
        assert once.checks.min_clearance >= gen.config.env.min_clearance
        assert once.scene.outline[:, 1].max() == pytest.approx(0.09)
        twice = g.replan(once, Obstacle.rectangle(0.10, 0.10), at=0.4)
        assert twice.switch_times == (0.25, 0.4)
        t = np.linspace(0.0, 0.4, 100)
        assert np.abs(twice.at(t).joint_angles - once.at(t).joint_angles).max() <= 1e-12
        assert twice.rate == old.rate and twice.to_dict()["switch_times_s"] == [0.25, 0.4]


def test_rate_and_options_carry_over(setup):
    gen, _, swing = setup
    new = gen.replan(swing, Obstacle.rectangle(0.10, 0.09), at=0.25, rate=500, clearance=0.025)
    assert new.rate == 500.0 and np.allclose(np.diff(new.time[:-1]), 1.0 / 500.0)
    assert new.checks.min_clearance >= 0.025 or not new.ok


def test_no_safe_continuation_is_flagged_or_raised_with_strict(setup):
    gen, _, swing = setup
    # a wall far taller than any swing clears, just ahead of the foot
    wall = Obstacle.rectangle(0.05, 0.45, center_y=0.45)
    new = gen.replan(swing, wall, at=0.2, fallback=None)
    assert not new.ok and new.reasons
    with pytest.raises(TrajectoryError):
        gen.replan(swing, wall, at=0.2, fallback=None, strict=True)


@pytest.mark.parametrize(
    "kw, error, match",
    [
        ({"at": 0.0}, ValueError, "at: expected a time in s within the swing"),
        ({"at": 9.0}, ValueError, "at: expected a time in s within the swing"),
        ({"at": "0.3"}, TypeError, "at: expected a time in seconds"),
        ({"at": 0.3, "pivot": "agent"}, TypeError, "pivot: not an option of replan"),
        ({"at": 0.3, "step_length": 0.6}, TypeError, "step_length: not an option of replan"),
        ({"at": 0.3, "smoothness": 1.0}, TypeError, "smoothness: not an option of replan"),
        ({"at": 0.3, "rate": 5.0}, ValueError, "rate: control rate must be between"),
    ],
)
def test_bad_arguments_are_refused(setup, kw, error, match):
    gen, _, swing = setup
    with pytest.raises(error, match=match):
        gen.replan(swing, Obstacle.rectangle(0.10, 0.09), **kw)


def test_a_foot_already_at_the_new_obstacle_and_other_legs_are_refused(setup):
    gen, _, swing = setup
    st = swing.at(np.array([0.3]))
    heel = st.heel[0]
    lo, hi = (
        max(0.21, heel[0] + 0.05),
        heel[0] + 0.19,
    )  # under the foot, ahead of the toe at the start
    around = Obstacle.rectangle(hi - lo, heel[1] + 0.05, center_y=0.5 * (lo + hi))
    with pytest.raises(ValueError, match="obstacle: at t=0.3000 s the foot .* is already inside"):
        gen.replan(swing, around, at=0.3)
    from dataclasses import replace

    other = replace(swing, curve=replace(swing.curve, lengths=(0.5, 0.45)))
    with pytest.raises(ValueError, match="kinematics.shin = 0.5 m, but the swing was timed for"):
        gen.replan(other, Obstacle.rectangle(0.10, 0.09), at=0.3)
    with pytest.raises(TypeError, match="swing: expected a TimedSwing"):
        gen.replan(
            gen.generate(Obstacle.rectangle(0.10, 0.05)), Obstacle.rectangle(0.1, 0.09), at=0.3
        )


@pytest.mark.parametrize("rate", [500.0, 1000.0])
def test_a_replanned_swings_exports_read_back_by_independent_clients(setup, tmp_path, rate):
    """The replanned swing's JSON curve, evaluated as its `evaluate` text says by the evaluator of
    tests/test_piecewise_export.py, is the swing's curve (C2 at every breakpoint, the switch's
    included, within the limits it claims), and its ROS 2 JointTrajectory is built and read back
    with rosbags (tests/test_export_clients.py's reader) bit for bit, at 500 Hz and 1 kHz."""
    import json

    from rosbags.typesys import Stores, get_typestore

    from jaxexo.swing.export import JOINT_NAMES

    from test_export_clients import JT, _check_message, _message
    from test_piecewise_export import JsonCurve, _agreement, _c2_jumps

    gen, cf, swing = setup
    old_cf = time_swing(cf.generate(Obstacle.rectangle(0.10, 0.05)), gen.config)
    for g, old in ((gen, swing), (cf, old_cf)):
        new = g.replan(old, Obstacle.rectangle(0.10, 0.09), at=0.25, rate=rate)
        assert new.ok
        doc = json.loads(new.to_json(tmp_path / "replanned.json"))
        assert doc["switch_times_s"] == [0.25]
        curve = JsonCurve(doc)
        err = _agreement(new, curve, dense=True)
        assert err[0] <= 1e-12 and err[1] <= 1e-9 and err[2] <= 1e-9, err
        assert max(_c2_jumps(curve)) < 1e-9
        planned = new.limits.planned()
        grid = np.arange(0.0, curve.duration, 1.0 / 20_000.0)
        _, v, a, j = curve.joints(np.concatenate([grid, curve.tb]))
        for x, lim in zip((v, a, j), (planned.velocity, planned.acceleration, planned.jerk)):
            assert np.all(np.abs(x) <= np.asarray(lim) * (1.0 + 1e-9))
        before = np.linspace(0.0, 0.25, 300)
        assert np.abs(curve.joints(before)[0] - old.at(before).joint_angles).max() <= 1e-12
        store = get_typestore(Stores.ROS2_HUMBLE)
        msg = _message(store, JT, json.loads(new.to_joint_trajectory(tmp_path / "ros.json")))
        back = store.deserialize_cdr(store.serialize_cdr(msg, JT), JT)
        _check_message(back, new, JOINT_NAMES)
