"""The choice of a population's exported member (jaxexo.train.selection): safety first, then the
wearer's cost against CFFTG, then validation success, then the seed; and the figures a score holds,
recomputed by hand from per-scene swings."""

from __future__ import annotations

import math

import numpy as np

from jaxexo.train import selection
from jaxexo.train.selection import WearerScore, choose_for_wearer, score_record


def _score(seed, safe, cost, validation=1.0):
    return WearerScore(
        seed=seed,
        validation_success=validation,
        safe=safe,
        both_safe=10,
        duration_median_s=1.0,
        duration_p95_s=1.2,
        lift_median_m=0.04,
        cost=cost,
    )


def test_safety_comes_before_comfort_then_validation_then_the_seed():
    # a quicker, lower swing never wins over a safer one
    assert choose_for_wearer([_score(0, 0.99, 2.5), _score(1, 1.0, 3.4)]) == 1
    # equally safe: the lower wearer's cost
    assert choose_for_wearer([_score(0, 1.0, 3.1), _score(1, 1.0, 2.9)]) == 1
    # nothing separates them on the scenes: validation success, then the lower seed
    assert choose_for_wearer([_score(5, 0.0, math.inf, 0.4), _score(6, 0.0, math.inf, 0.7)]) == 1
    assert choose_for_wearer([_score(6, 1.0, 3.0), _score(5, 1.0, 3.0)]) == 1


def test_a_score_is_the_ratios_to_cfftg_on_the_scenes_both_swing_safely():
    rl = selection._Figures(
        ok=np.array([True, True, True, False, True]),
        duration=np.array([1.0, 1.2, 1.4, 9.0, 1.1]),
        lift=np.array([0.03, 0.05, 0.04, 0.5, 0.06]),
    )
    ref = selection._Figures(
        ok=np.array([True, True, True, True, False]),
        duration=np.array([1.0, 1.0, 1.0, 1.0, 1.0]),
        lift=np.array([0.04, 0.04, 0.04, 0.04, 0.04]),
    )
    s = selection._score(3, 0.9, rl, ref)
    # both safe: scenes 0-2; medians and the p95 (linear interpolation: 1.2 + 0.9 * 0.2) by hand
    assert s.safe == 0.8 and s.both_safe == 3
    assert math.isclose(s.duration_median_s, 1.2) and math.isclose(s.duration_p95_s, 1.38)
    assert math.isclose(s.lift_median_m, 0.04)
    assert math.isclose(s.cost, 1.2 / 1.0 + 1.38 / 1.0 + 0.04 / 0.04)
    none = selection._score(
        4, 0.2, rl, selection._Figures(ok=np.zeros(5, bool), duration=ref.duration, lift=ref.lift)
    )
    assert none.both_safe == 0 and none.cost == math.inf
    assert score_record(none)["cost"] is None and score_record(none)["seed"] == 4
