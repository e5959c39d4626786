"""``jaxexo train``: ``run_training`` takes the run directory's lock and hands one agent (``OneAgent``,
its environments split over the CPU devices) or a population (jaxexo.train.population) to the chunk
loop (jaxexo.train.engine). The run directory, model selection and resume: docs/training.md; what a
run refuses and how it recovers: docs/reliability.md.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import jax
import numpy as np

from jaxexo.config import Config, ConfigError, check_seed
from jaxexo.storage.rundir import TrainingDiverged, run_lock  # noqa: F401 (read as driver.TrainingDiverged)
from jaxexo.train import run_files
from jaxexo.train.engine import Placement, run_chunks
from jaxexo.train.evaluate import make_validator
from jaxexo.train.lanes import finite
from jaxexo.train.records import ChunkOut
from jaxexo.train.trainer import Hyperparams, Trainer


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
    check_seed(
        seed, "--seed", cfg.train.population
    )  # before anything is made (PRNGKey overflows past it)
    with run_lock(out, "train", create=not resume, scratch=("config.toml",)):
        if cfg.train.population > 1:
            # K agents as one compiled program, the best on validation exported (jaxexo.train.population).
            from jaxexo.train.population import run_population

            return run_population(cfg, out, seed, resume, progress, eval_episodes)
        return run_chunks(cfg, out, seed, resume, progress, eval_episodes, OneAgent)


class OneAgent(Placement):
    """One agent whose environments are split over the CPU cores exposed as JAX devices (data parallel,
    jaxexo.train.devices; the CLI sets this up). The device count changes the random streams: a run is
    reproducible on the same count."""

    def __init__(self, cfg: Config, seed: int):
        self.cfg, self.seed, self.size = cfg, seed, 1
        self.trainer = Trainer(cfg, devices=jax.local_devices())
        self.n_devices = len(self.trainer.devices or [0])
        self.hyper = Hyperparams.from_config(cfg)
        self.n_chunk = run_files.chunking(cfg, self.trainer)[0]
        self._run = jax.jit(self.trainer.run, static_argnums=2)

    @functools.cached_property
    def _validate(self):
        # Made on first use: a refused resume draws no validation layouts.
        return make_validator(self.cfg, self.trainer.net)

    def check_resume(self, raw, ckpt):
        if raw["book"]["devices"] != self.n_devices:
            raise ConfigError(
                f"--resume: the run used {raw['book']['devices']} device(s), this process has "
                f"{self.n_devices}; resume it on the same number of CPU devices"
            )

    def init(self):
        return self.resume(jax.jit(self.trainer.init)(jax.random.PRNGKey(self.seed), self.hyper))

    def saved(self, ts):
        return ts

    def resume(self, saved):
        # The state laid out as the chunks return it, so that every chunk calls one compiled program
        # (Trainer.place: else the second chunk, on a state split over the devices, compiles it again).
        return self.trainer.place(saved)

    def chunk(self, ts):
        ts, m = self._run(ts, self.hyper, self.n_chunk)
        m = jax.tree.map(np.asarray, m)
        ok = bool(finite(np, ts, m))
        score = self._validate(ts.params) if ok else math.nan
        return ChunkOut(ts, jax.tree.map(lambda x: x[None], m), np.array([score]), np.array([ok]))
