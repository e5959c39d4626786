"""Where a run's K agents live (jaxexo.train.engine.Placement): ``OneAgent``, one agent whose
environments are split over the CPU devices, and ``Members``, K members vmapped in lanes
(jaxexo.train.population). Both hand the chunk loop the same records and files, with an agent axis."""

from __future__ import annotations

import functools
import math

import jax
import numpy as np

from jaxexo.config import Config, ConfigError
from jaxexo.train import population
from jaxexo.train.engine import Placement, chunking
from jaxexo.train.evaluate import make_validator
from jaxexo.train.lanes import finite
from jaxexo.train.records import ChunkOut
from jaxexo.train.trainer import Hyperparams, Trainer


def placement_for(cfg: Config) -> type[Placement]:
    """A population's members in lanes; one agent data parallel, which is faster for one agent and
    whose arithmetic is not a member's (docs/training.md, Group-size independence): a run keeps the
    program its policy was trained with."""
    return Members if cfg.train.population > 1 else OneAgent


class OneAgent(Placement):
    """One agent whose environments are split over the CPU cores exposed as JAX devices (data parallel,
    jaxexo.train.devices; the CLI sets this up). The device count changes the random streams: a run is
    reproducible on the same count."""

    def __init__(self, cfg: Config, seed: int):
        self.cfg, self.seed, self.size = cfg, seed, 1
        self.trainer = Trainer(cfg, devices=jax.local_devices())
        self.n_devices = len(self.trainer.devices or [0])
        self.title = f"train {cfg.train.trace} {cfg.train.control}"
        self.hyper = Hyperparams.from_config(cfg)
        self.n_chunk = chunking(cfg, self.trainer)[0]
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
        return self.trainer.place(
            jax.jit(self.trainer.init)(jax.random.PRNGKey(self.seed), self.hyper)
        )

    def saved(self, ts):
        return jax.tree.map(lambda x: np.asarray(x)[None], ts)

    def resume(self, saved):
        # The state laid out as the chunks return it, so that every chunk calls one compiled program
        # (Trainer.place: else the second chunk, on a state split over the devices, compiles it again).
        return self.trainer.place(jax.tree.map(lambda x: np.asarray(x)[0], saved))

    def chunk(self, ts):
        ts, m = self._run(ts, self.hyper, self.n_chunk)
        m = jax.tree.map(np.asarray, m)
        ok = bool(finite(np, ts, m))
        score = self._validate(ts.params) if ok else math.nan
        return ChunkOut(ts, jax.tree.map(lambda x: x[None], m), np.array([score]), np.array([ok]))


class Members(Placement):
    """K members vmapped in lanes (jaxexo.train.population.Population)."""

    def __init__(self, cfg: Config, seed: int):
        self.size = cfg.train.population
        self.pop = population.Population(cfg, range(seed, seed + self.size))
        self.trainer, self.n_devices = self.pop.trainer, len(self.pop.devices)
        self.title = f"train population of {self.size} ({self.n_devices} device(s))"

    def check_resume(self, raw, ckpt):
        if (raw["book"]["devices"] == 1) != (self.n_devices == 1):
            # One device compiles an unpartitioned program, several a partitioned one: their arithmetic
            # differs in the last bits (population_devices), so the rest of the run would not be this run's.
            need = "one CPU device" if raw["book"]["devices"] == 1 else "two or more CPU devices"
            raise ConfigError(
                f"--resume: the population ran on {raw['book']['devices']} device(s), this process "
                f"gives it {self.n_devices}; resume it with {need}"
            )

    def init(self):
        return self.pop.init()

    def saved(self, ts):
        return self.pop.real(ts)

    def resume(self, saved):
        return jax.device_put(self.pop.pad(saved))

    def chunk(self, ts):
        ts, m, score, ok = self.pop.chunk(ts)
        return ChunkOut(ts, self.pop.real(m), self.pop.real(score), self.pop.real(ok))
