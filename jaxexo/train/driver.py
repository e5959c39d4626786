"""``jaxexo train``: drive the compiled trainer in chunks, with progress, metrics, checkpoints and resume.

Run directory:
- config.toml        the resolved config
- checkpoint.msgpack the TrainState after the last finished chunk, the best parameters so far and the
                     bookkeeping (chunks done, wall time, best score), in one atomic write
- checkpoint.json    a readable copy of that bookkeeping (informational; resume reads the msgpack)
- metrics.jsonl      one line per chunk: counters and rates reduced inside the compiled scan
- policy.npz         the exported greedy policy (jaxexo.storage.policy_file; NumPy-only to load)
- training_curve.png return and success rate against episodes (thesis Fig. 3.4)
- eval.json          greedy rollouts on the test layouts (jaxexo.train.evaluate)
(names, checkpoint reading and checks, rows, export: jaxexo.train.run_files; the chunk loop with resume,
checkpoints, divergence, progress and export: jaxexo.train.engine, shared with populations, of which
``OneAgent`` here is the one-agent placement)

Population (``[train] population = K > 1``): K seeds of the config trained together, the best member's
best chunk exported; jaxexo.train.population has the program and the per-member files.

Model selection: after every chunk the greedy policy is scored (strict success) on validation
layouts drawn from the training distribution; the best parameters are exported (later chunks win
ties). The held-out test obstacles are never used for this choice.

Resume: the same chunk program runs from the restored state, so a resumed run ends bit-identical to
an uninterrupted one (tests/test_driver.py checks it). metrics.jsonl is cut back to the checkpoint's
chunks first (rows written after it are recomputed identically).

Reliability (docs/reliability.md; tests/test_reliability.py):
- the run holds an exclusive lock on the directory (jaxexo.storage.rundir) from start to end: a second
  ``jaxexo train``/``sweep`` there is refused; a killed run's lock vanishes with it;
- a new run needs an empty or absent directory (a finished policy.npz, a sweep's best/, the remains of a
  crashed run are never overwritten or appended to);
- the checkpoint carries a sha256 (jaxexo.storage.checkpoint) and its trees must match this config's
  network and state in structure, shape and dtype, or resume is refused naming the file;
- the checkpoint records the config the run started with: a resume with any other config (config.toml
  edited along with it) is refused naming the first differing field; a run past its first chunk
  whose checkpoint was deleted (checkpoint.json, or more than one metrics row, remain) is refused;
- a chunk whose parameters, target parameters or metrics (the loss among them) are not finite
  (jaxexo.train.lanes.finite, the population's and the sweep's rule too) marks the run diverged: the
  row says so, training stops, no checkpoint is written for it, only the best finite parameters (if a
  chunk produced any) are exported, and TrainingDiverged is raised (the CLI exits 3).
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
