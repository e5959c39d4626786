"""A limit added as a new constraint class (jaxexo.swing.limits' contract), with no change to the
passes, the final law or the proof: the swing heel's speed. A swing timed with it keeps it on its
curve sampled densely (finite differences at 2 kHz, independent of the timing's own bounds), is
slower than without it, and a limit that never binds leaves every timed swing bit for bit as the
default limits time it. Rows with an offset (a torque's gravity) in the passes: the plain recurrence."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.config import load_config
from jaxexo.inference.scenarios import training_scenarios
from jaxexo.swing.curve import heel_derivatives
from jaxexo.swing.limits import DeviceLimits, Rows
from jaxexo.swing.timing import time_swings

from conftest import ROOT

RATE = 2000.0  # Hz: the independent check's finite differences


@dataclass(frozen=True, eq=False)
class HeelSpeed:
    """|d heel / dt| <= limit (m/s, (1,)), the swing heel in the sagittal plane; ``lengths``:
    (thigh, shin) m."""

    limit: np.ndarray
    lengths: tuple
    order = 1
    label = "heel speed"

    def rows(self, view) -> Rows:
        """|heel'(s)| s' at each grid point: the heel's derivative along the path (B, K, 1)."""
        b, k, j = view.q.shape
        _, dheel = heel_derivatives(
            self.lengths, 0.0, [view.q.reshape(-1, j), view.dq.reshape(-1, j)]
        )
        return Rows(np.sqrt((dheel**2).sum(axis=-1)).reshape(b, k, 1))

    def curve_bound(self, d):
        """|heel-dot| <= sum_i L_i |phi_i-dot| (the legs' segments, phi their absolute angles:
        hip, hip + knee of each leg) <= sum_j lever_j |q_j-dot|, from the proof's bounds on
        |q-dot| (J, ...): (1, ...)."""
        thigh, shin = self.lengths
        lever = np.array([thigh + shin, shin, thigh + shin, shin])
        return np.tensordot(lever, d[0], axes=1)[None], None


@pytest.fixture(scope="module")
def swings():
    config = load_config(ROOT / "configs" / "default.toml")
    scenes = training_scenarios(config, 6, seed=3)
    batch = CFFTG(config).generate_batch(
        [s.obstacle for s in scenes],
        pivot=[s.pivot for s in scenes],
        start_y=[s.start_y for s in scenes],
        step_length=[s.step_length for s in scenes],
    )
    return config, [batch[i] for i in range(len(batch))]


def _heel_speeds(swing) -> np.ndarray:
    """The heel's mean speed over each sample interval of the curve at RATE (m/s): never above its
    largest speed on the interval."""
    t = np.arange(0.0, swing.duration, 1.0 / RATE)
    heel = swing.curve.at(np.append(t, swing.duration)).heel
    return np.sqrt((np.diff(heel, axis=0) ** 2).sum(axis=1)) / np.diff(np.append(t, swing.duration))


def test_a_heel_speed_limit_added_as_a_class_is_kept_on_the_timed_curve(swings):
    config, trajs = swings
    default = DeviceLimits.from_config(config)
    lengths = (config.kinematics.thigh, config.kinematics.shin)
    plain = time_swings(trajs, config, RATE, default)
    fastest = min(float(_heel_speeds(s).max()) for s in plain)
    limit = 0.6 * fastest  # binds on every swing
    limits = replace(default, extra=(HeelSpeed(np.array([limit]), lengths),))
    timed = time_swings(trajs, config, RATE, limits)
    planned = limit * (1.0 - default.headroom)
    for before, after in zip(plain, timed):
        assert after.within_limits
        assert after.duration > before.duration
        assert _heel_speeds(after).max() <= planned
        # The joints' own limits still hold.
        assert np.all(after.peak_velocity <= limits.planned().velocity)
    assert limits.to_dict()["other"] == ["heel speed"]


def test_a_limit_that_never_binds_changes_no_timed_swing(swings):
    config, trajs = swings
    default = DeviceLimits.from_config(config)
    loose = HeelSpeed(np.array([1e6]), (config.kinematics.thigh, config.kinematics.shin))
    for a, b in zip(
        time_swings(trajs, config, limits=default),
        time_swings(trajs, config, limits=replace(default, extra=(loose,))),
    ):
        assert a.duration == b.duration and a.within_limits == b.within_limits
        np.testing.assert_array_equal(a.joint_angles, b.joint_angles)
        np.testing.assert_array_equal(a.peak_jerk, b.peak_jerk)


def test_the_passes_with_an_offset_equal_the_plain_recurrence():
    """Rows with an offset (a torque's gravity: -bound <= a s'' + b s'^2 + c <= bound): the passes
    equal the plain recurrence on the admissible s'' interval, reach[i-1] = clip(reach[i] - 2 ds
    L_i(reach[i])), x[i+1] = clip(x[i] + 2 ds U_i(x[i])), under the same largest speeds."""
    from jaxexo.swing.time_law import max_speed_curve, topp

    rng = np.random.default_rng(4)
    b, k = 3, 120
    a = rng.uniform(0.5, 2.0, (b, k, 4)) * rng.choice([-1.0, 1.0], (b, k, 4))
    bb = 5.0 * rng.normal(size=(b, k, 4))
    bound = np.array([15.0, 20.0, 15.0, 20.0])
    c = rng.uniform(-0.6, 0.6, (b, k, 4)) * bound
    ds = 1.0 / (k - 1)
    rows = Rows(a, bb, c, bound)
    x, _ = topp(rows, ds)
    xmax = max_speed_curve(rows)

    def interval(i, j, v):
        ends = np.stack([(-bound - c[i, j] - bb[i, j] * v), (bound - c[i, j] - bb[i, j] * v)])
        ends = ends / a[i, j]
        return ends.min(axis=0).max(), ends.max(axis=0).min()

    for i in range(b):
        reach = np.zeros(k)
        for j in range(k - 1, 0, -1):
            step = reach[j] - 2.0 * ds * interval(i, j, reach[j])[0]
            reach[j - 1] = min(max(step, 0.0), xmax[i, j - 1])
        plain = np.zeros(k)
        for j in range(k - 1):
            step = plain[j] + 2.0 * ds * interval(i, j, plain[j])[1]
            plain[j + 1] = min(max(step, 0.0), reach[j + 1])
        np.testing.assert_allclose(x[i], plain, rtol=1e-9, atol=1e-12)
        assert plain[1:-1].min() > 0.0
