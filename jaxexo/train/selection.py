"""Which member of a population is exported: the one a wearer would choose. Every candidate (a
member's best chunk) is swung by the NumPy generator, RL alone, on validation scenes of the training
distribution, each swing timed, beside CFFTG on the same scenes: the most safe swings win, then the
least wearer's cost (WearerScore.cost), then validation success, then the lowest seed (the method:
docs/training.md, Populations).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import jax
import numpy as np

from jaxexo.config import Config
from jaxexo.inference import time_swing, time_swings
from jaxexo.inference.registry import generator_class
from jaxexo.inference.scenarios import training_scenarios
from jaxexo.physics.scenarios import Scenario, batch_options
from jaxexo.summary import Summary

# Scenes every candidate is swung on: enough that one unsafe swing in a hundred shows, few enough that
# the choice costs seconds (about 10 ms per swing and generator with its timing).
SELECTION_SCENES = 100
SELECTION_SEED = 777  # the JAX validation set's seed (jaxexo.train.evaluate.VALIDATION_SEED)


@dataclass(frozen=True)
class WearerScore:
    """One candidate's figures on the selection scenes (SI units)."""

    seed: int
    validation_success: float  # greedy validation success of the candidate's chunk in training
    safe: float  # share of the scenes swung safely, RL alone
    both_safe: int  # scenes both the candidate and CFFTG swing safely
    duration_median_s: float  # timed swing, complete to the floor, on those scenes
    duration_p95_s: float
    lift_median_m: float  # heel peak above the obstacle's top
    cost: float  # the wearer's cost (docs/training.md); inf when no scene is both safe

    def key(self) -> tuple:
        """Sort key: best first (most safe, least cost, best validation, lowest seed)."""
        return (-self.safe, self.cost, -self.validation_success, self.seed)


@dataclass(frozen=True)
class _Figures:
    ok: np.ndarray  # (n,) bool: safe swing
    duration: np.ndarray  # (n,) s
    lift: np.ndarray  # (n,) m


def _swing(gen, scenes: list[Scenario], cfg: Config, **options) -> _Figures:
    obstacles = [s.obstacle for s in scenes]
    batch = list(gen.generate_batch(obstacles, **batch_options(scenes), **options))
    duration = _durations(batch, cfg)
    lift = np.array([t.heel[:, 1].max() - o.height for t, o in zip(batch, obstacles)])
    # A swing that cannot be timed is not one a wearer can be given: unsafe on its scene.
    return _Figures(np.array([t.ok for t in batch]) & np.isfinite(duration), duration, lift)


def _durations(batch: list, cfg: Config) -> np.ndarray:
    """Each swing's timed duration (s), NaN where the timing refuses the swing (a ValueError: a
    member that pushes into the ground never moves its joints, so there is nothing to time). The
    swings are timed together (one batched TOPP), and one by one only when that fails, so that one
    such swing costs its own scene, not the member's other scenes or the run."""
    try:
        return np.array([t.duration for t in time_swings(batch, cfg)])
    except ValueError:
        pass
    out = np.full(len(batch), math.nan)
    for i, traj in enumerate(batch):
        try:
            out[i] = time_swing(traj, cfg).duration
        except ValueError:
            continue
    return out


def _score(seed: int, validation: float, rl: _Figures, ref: _Figures) -> WearerScore:
    both = rl.ok & ref.ok
    if not both.any():
        return WearerScore(
            seed, validation, float(rl.ok.mean()), 0, math.nan, math.nan, math.nan, math.inf
        )
    d, d_ref = Summary.of(rl.duration[both]), Summary.of(ref.duration[both])
    lift = Summary.of(rl.lift[both]).median
    cost = (
        d.median / d_ref.median
        + d.p95 / d_ref.p95
        + lift / max(Summary.of(ref.lift[both]).median, 1e-3)
    )
    return WearerScore(
        seed, validation, float(rl.ok.mean()), int(both.sum()), d.median, d.p95, lift, cost
    )


@dataclass(frozen=True)
class Candidate:
    """A population member's exported best chunk."""

    seed: int
    validation_success: float
    policy: Path


def wearer_scores(cfg: Config, candidates: list[Candidate]) -> list[WearerScore]:
    """Each candidate scored on SELECTION_SCENES scenes of ``cfg``'s training distribution (seed
    SELECTION_SEED), in the order given."""
    scenes = training_scenarios(cfg, SELECTION_SCENES, SELECTION_SEED)
    ref = _swing(generator_class("cfftg").from_config(cfg), scenes, cfg)
    return [
        _score(
            c.seed,
            c.validation_success,
            _swing(generator_class("rl").from_policy(c.policy), scenes, cfg, fallback=None),
            ref,
        )
        for c in candidates
    ]


def choose_for_wearer(scores: list[WearerScore]) -> int:
    """The index of the best score (WearerScore.key)."""
    return min(range(len(scores)), key=lambda i: scores[i].key())


def score_record(score: WearerScore) -> dict:
    """A score as eval.json writes it (JSON: a cost without a value is null)."""
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in asdict(score).items()
    }


@dataclass(frozen=True)
class Selection:
    """A population's choice: the member exported, eval.json's ``selection`` and its time."""

    exported: int
    scores: list[dict]  # score_record of each candidate (empty: one candidate, exported unscored)
    seconds: float


def choose_member(cfg: Config, out: Path, trainer, track, seeds: list[int]) -> Selection:
    """The member to export of a population with candidates (jaxexo.train.records.Track): every
    candidate (a member that finished a chunk and never diverged) exported to
    ``members/seed_<seed>.npz`` and scored as a wearer gets it; one candidate is exported unscored."""
    from jaxexo.train.export import export_policy

    t0 = time.perf_counter()
    ok = track.candidates()
    if len(ok) == 1:
        return Selection(ok[0], [], time.perf_counter() - t0)
    (out / "members").mkdir(exist_ok=True)
    candidates = [
        Candidate(
            seeds[i],
            float(track.score[i]),
            export_policy(
                out / "members" / f"seed_{seeds[i]}.npz",
                cfg,
                trainer,
                jax.tree.map(lambda x: x[i], track.params),
            ),
        )
        for i in ok
    ]
    scores = wearer_scores(cfg, candidates)
    return Selection(
        ok[choose_for_wearer(scores)], [score_record(s) for s in scores], time.perf_counter() - t0
    )
