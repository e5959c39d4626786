"""``[train] population = K``: K agents of one config (seeds seed .. seed + K - 1) trained as one
compiled program (``Population``: ``jit(shard_map(lax.map(vmap(member))))`` over the CPU devices in
blocks of LANES, jaxexo.train.lanes), placed in the chunk loop by jaxexo.train.placements.Members.
Why populations and the choice of the exported member: docs/training.md (Populations); the choice
itself: jaxexo.train.selection.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from jaxexo.config import Config, ConfigError
from jaxexo.train.engine import chunking
from jaxexo.train.evaluate import make_rollouts, validation_set
from jaxexo.train.lanes import LANES, agent_program, over_lanes, padded_agents
from jaxexo.train.trainer import Hyperparams, Trainer


def population_devices(n_members: int, devices) -> list:
    """The devices a population uses: as many as it fills with whole blocks of LANES members, but at
    least two where there are two. XLA compiles a program over one device without partitioning and
    over several with it, and the two differ in the last bits (measured: a member's bytes are equal
    on 2 and 4 devices, not on 1 and 2), so a population never drops to one device because it is
    small: its members then train as they do in a larger population or a sweep on the same machine."""
    devices = list(devices)
    return devices[: min(len(devices), max(2, -(-n_members // LANES)))]


class Population:
    """The compiled programs of a population of one config: ``init(seeds)`` and ``chunk(state)``.

    The state has a leading member axis padded to ``padded`` (copies of the first member, whose
    results are dropped); ``real(x)`` cuts any output back to the real members. ``devices``: the
    devices to spread over as given (a check across device counts), by default population_devices
    of the local ones."""

    def __init__(self, cfg: Config, seeds, devices=None, n_chunk: int | None = None):
        self.cfg, self.seeds = cfg, [int(s) for s in seeds]
        if not self.seeds:
            raise ConfigError("train.population: a population needs at least one member")
        self.trainer = Trainer(cfg)  # one device per member: no data parallelism inside a member
        local = population_devices(len(self.seeds), jax.local_devices())
        self.devices = local if devices is None else list(devices)
        self.padded = padded_agents(len(self.seeds), len(self.devices))
        self.n_chunk = n_chunk if n_chunk is not None else chunking(cfg, self.trainer)[0]
        hyper = Hyperparams.from_config(cfg)
        self.hyper = jax.tree.map(lambda x: np.stack([np.asarray(x)] * self.padded), hyper)
        env, self.val_params, self.val_layouts = validation_set(cfg)
        rollouts = make_rollouts(env, self.trainer.net.apply, cfg.env.max_steps)
        run = agent_program(self.trainer, rollouts, self.n_chunk)

        def member(ts, hyper, layouts, vparams):
            ts, m, out, ok = run(ts, hyper, layouts, vparams)
            return ts, m, jnp.mean(out.success.astype(jnp.float32)), ok

        self._init = over_lanes(self.trainer.init, self.devices, n_args=2)
        self._chunk = over_lanes(member, self.devices, n_args=2, shared=2)

    @property
    def size(self) -> int:
        return len(self.seeds)

    def pad(self, tree):
        """Members -> the padded batch (copies of the first member after the real ones)."""
        extra = self.padded - self.size
        return jax.tree.map(
            lambda x: np.concatenate([np.asarray(x)] + [np.asarray(x)[:1]] * extra), tree
        )

    def real(self, tree):
        return jax.tree.map(lambda x: np.asarray(x)[: self.size], tree)

    def init(self):
        keys = np.stack([np.asarray(jax.random.PRNGKey(s)) for s in self.seeds])
        return self._init(self.pad(keys), self.hyper)

    def chunk(self, ts):
        """One chunk for every member: the state, UpdateMetrics [padded, n_chunk], validation
        success [padded] and ``finite`` [padded]."""
        return self._chunk(ts, self.hyper, self.val_layouts, self.val_params)
