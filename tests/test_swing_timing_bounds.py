"""Bounded timing: a swing of a model that learned nothing costs a bounded amount to time.
The recorded swings (tests/data/wandering_swings.json) are thesis config 3's test swings as
``jaxexo reproduce`` evaluates them: a policy that wanders, whose time-optimal law at the device
limits takes 99 s and 182 s (117 s and 189 s slowed to them on 46d0ad3). Timing them is bounded in sizes (samples, joint samples) and memory,
and their verdicts say what happened: over a limit, not ok, with the reason in the notes."""

from __future__ import annotations

import json
import tracemalloc

import numpy as np

from jaxexo.config import MAX_SWING_DURATION, load_config, packaged_config, scalar_params
from jaxexo.evaluation.metrics import device_metrics
from jaxexo.swing import timing
from jaxexo.swing.timing import time_swings

from conftest import ROOT, recorded_swing

THESIS_3 = load_config(packaged_config("thesis/3"))
SP = scalar_params(THESIS_3)
RATE = 100.0


def _swing(rec: dict, heel=None):
    return recorded_swing(SP, rec, heel)


RECORDS = json.loads((ROOT / "tests" / "data" / "wandering_swings.json").read_text())["swings"]
WANDERING = [_swing(r) for r in RECORDS]


def test_a_wandering_swing_is_sampled_as_the_longest_swing_at_most_and_said_over_a_limit():
    for sw in time_swings(WANDERING, THESIS_3, rate=RATE):
        # Sizes, not times: at most the longest swing's samples (46d0ad3: 11,724 and 18,857).
        assert len(sw.time) <= MAX_SWING_DURATION * RATE + 1
        assert sw.duration <= MAX_SWING_DURATION * (1 + 1e-12)
        # Honest: sped up to the longest swing, over a limit, not ok, and the notes say why.
        assert not sw.within_limits and not sw.ok and sw.slowdown < 1.0
        assert any("longer than the longest swing" in n for n in sw.notes), sw.notes
        assert any("limits" in r and "exceeded" in r for r in sw.reasons)
        planned = sw.limits.planned()
        assert np.any(np.asarray(sw.peak_velocity) > planned.velocity) or np.any(
            np.asarray(sw.peak_acceleration) > planned.acceleration
        )


def _peak_bytes(fn) -> int:
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_device_metrics_memory_does_not_grow_with_the_swings(monkeypatch):
    """device_metrics (jaxexo reproduce's evaluation) times and keeps a chunk of swings at a time:
    four times the swings, in chunks of two, peak at no more memory than two (on 46d0ad3 one batch
    held them all: 12 GB and growing for config 3's 2,000 test swings)."""
    monkeypatch.setattr(timing, "CHUNK", 2, raising=False)
    m = device_metrics(WANDERING, THESIS_3)
    assert not m.within_limits.any()
    assert np.all(m.swing_s <= MAX_SWING_DURATION * (1 + 1e-12)) and np.all(m.swing_s > 1.0)
    two = _peak_bytes(lambda: device_metrics(WANDERING, THESIS_3))
    eight = _peak_bytes(lambda: device_metrics(WANDERING * 4, THESIS_3))
    assert eight < 1.3 * two, (eight / 1e6, two / 1e6)


def test_joint_samples_bounded_on_a_path_that_mostly_stands_still():
    """A heel that trembles by rounding noise and then jumps: the refinement's unit is the median
    step (1e-13 m here), which asked for ~1e11 joint samples on 46d0ad3 (MemoryError)."""
    heel = np.asarray(RECORDS[0]["heel"], np.float64)
    start, end = heel[0], heel[-1]
    n = len(heel)
    tremble = start + np.outer(np.arange(n - 2) % 2, [1e-13, 0.0])
    path = np.vstack([tremble, [0.5 * (start + end) + [0.0, 0.1]], end])
    traj = _swing(RECORDS[0], path)
    q = timing._joint_samples(SP, traj)
    assert len(q) <= timing.REFINE_BUDGET + n
    # The trajectory's own joints are kept exactly among them.
    assert np.array_equal(q[0], np.unwrap(traj.joint_angles, axis=0)[0])
    sw = time_swings([traj], THESIS_3, rate=RATE)[0]
    assert len(sw.time) <= MAX_SWING_DURATION * RATE + 1
