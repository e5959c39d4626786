"""``jaxexo train``: ``run_training`` takes the run directory's lock and hands the run's agents, placed
where they live (jaxexo.train.placements: one agent or a population), to the one chunk loop
(jaxexo.train.engine). The run directory, model selection and resume: docs/training.md; what a run
refuses and how it recovers: docs/reliability.md.
"""

from __future__ import annotations

from pathlib import Path

from jaxexo.config import Config, check_seed
from jaxexo.config.memory import check_memory
from jaxexo.storage.rundir import TrainingDiverged, run_lock  # noqa: F401 (read as driver.TrainingDiverged)
from jaxexo.train.engine import run_chunks
from jaxexo.train.placements import placement_for


def run_training(
    cfg: Config,
    out: str | Path,
    seed: int = 0,
    resume: bool = False,
    progress: bool = True,
    eval_episodes: int | None = None,
) -> dict:
    """Train, write the run directory, and return eval.json's content. Holds the directory's lock
    throughout; raises TrainingDiverged (after writing what can be trusted) if the run diverged."""
    out = Path(out)
    # Before anything is made (PRNGKey overflows past the seed's range; the machine may not hold K).
    check_seed(seed, "--seed", cfg.train.population)
    check_memory(cfg)
    with run_lock(out, "train", create=not resume, scratch=("config.toml",)):
        return run_chunks(cfg, out, seed, resume, progress, eval_episodes, placement_for(cfg))
