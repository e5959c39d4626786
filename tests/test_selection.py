"""The choice of a population's exported member (jaxexo.train.selection): safety first, then the
wearer's cost against CFFTG, then validation success, then the seed; and the figures a score holds,
recomputed by hand from per-scene swings."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from jaxexo.config.toml_io import config_to_toml
from jaxexo.inference import TrajectoryGenerator, time_swings
from jaxexo.inference.scenarios import training_scenarios
from jaxexo.physics.scenarios import batch_options
from jaxexo.storage.policy_file import load_policy, save_policy
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


REFERENCE_POLICY = Path(__file__).resolve().parent / "data" / "reference" / "policy.npz"
DOWN = 27  # the move straight down (270 degrees): at the start, on the ground, it does not move


def policy_that_pushes_into_the_ground(path: Path, src: Path = REFERENCE_POLICY) -> Path:
    """The policy ``src`` (default: the reference policy) with its output layer replaced by one that always prefers the move
    straight down, unshielded (the shield would offer it other moves): its heel never leaves the
    start, so its joints never move and the timing has nothing to time (a member of a population
    can learn this)."""
    pol = load_policy(REFERENCE_POLICY)
    meta = {
        k: v for k, v in pol.metadata.items() if k not in ("format", "format_version", "sha256")
    }
    cfg = TrajectoryGenerator.load(REFERENCE_POLICY).config
    meta["config_toml"] = config_to_toml(
        dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, shield=False))
    )
    kernels, biases = list(pol.kernels), list(pol.biases)
    kernels[-1] = np.zeros_like(kernels[-1])
    biases[-1] = np.zeros_like(biases[-1])
    biases[-1][DOWN] = 1.0
    return save_policy(path, kernels, biases, pol.norm_scales, pol.norm_biases, meta)


def test_a_member_that_cannot_be_timed_scores_unsafe_and_the_others_are_chosen(tmp_path):
    """A population member whose swings cannot be timed (its joints never move) ended the
    run while the member was chosen (a ValueError from the timing). It now scores as unsafe on those
    scenes, the other members' scores are what they are without it, and one member is chosen."""
    stuck = policy_that_pushes_into_the_ground(tmp_path / "stuck.npz")
    cfg = TrajectoryGenerator.load(REFERENCE_POLICY).config
    good = selection.Candidate(1, 0.5, REFERENCE_POLICY)
    scores = selection.wearer_scores(cfg, [selection.Candidate(2, 0.9, stuck), good])
    assert scores[0].safe == 0.0 and scores[0].both_safe == 0 and scores[0].cost == math.inf
    assert scores[1] == selection.wearer_scores(cfg, [good])[0]
    assert scores[1].safe > 0.5
    assert choose_for_wearer(scores) == 1


def test_a_swing_that_cannot_be_timed_costs_its_own_scene_only(tmp_path):
    """Among swings timed together, one the timing refuses gets no duration and is unsafe; the
    others keep the durations they have when timed without it."""
    stuck = TrajectoryGenerator.load(policy_that_pushes_into_the_ground(tmp_path / "stuck.npz"))
    gen = TrajectoryGenerator.load(REFERENCE_POLICY)
    scenes = training_scenarios(gen.config, 4, 5)
    kw = batch_options(scenes)
    obstacles = [s.obstacle for s in scenes]
    moving = list(gen.generate_batch(obstacles, **kw))
    still = list(stuck.generate_batch(obstacles, fallback=None, **kw))
    assert np.all(still[2].heel == still[2].heel[0])  # the heel never leaves its start
    with pytest.raises(ValueError, match="nothing to time"):
        time_swings([still[2]], gen.config)
    mixed = moving[:2] + still[2:3] + moving[3:]
    duration = selection._durations(mixed, gen.config)
    alone = [t.duration for t in time_swings(moving[:2] + moving[3:], gen.config)]
    assert np.isnan(duration[2])
    np.testing.assert_array_equal(np.delete(duration, 2), alone)
