"""How a sweep is cut into chunks (NumPy only): the memory one agent needs, the budget, and the chunk
sizes, one per group so that each group compiles once. See docs/training.md, "Hyperparameter sweeps".
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import asdict, dataclass
from pathlib import Path

from jaxexo.config import Config, ConfigError, num_updates
from jaxexo.physics.actions import NUM_ACTIONS  # one definition each
from jaxexo.physics.actions import obs_dim as _obs_dim
from jaxexo.sweep.spec import Sweep

# About this many env steps per chunk (a minute or so at the sweep program's throughput,
# docs/benchmarks.md#sweeps).
CHUNK_ENV_STEPS = 64_000_000
# Outline edges and reward terms make the environment step's temporaries about this many floats per
# environment and outline vertex, plus a constant (measured from XLA's buffer assignment, rounded up).
_STEP_FLOATS_PER_VERTEX, _STEP_FLOATS = 32, 256
_SAFETY = 2.0


def default_memory_budget() -> int:
    """Half the memory available now (MemAvailable), or 2 GiB where /proc/meminfo is missing."""
    try:
        m = re.search(r"MemAvailable:\s*(\d+) kB", Path("/proc/meminfo").read_text())
        if m:
            return int(m.group(1)) * 1024 // 2
    except OSError:
        pass
    return 2 * 2**30


def check_memory_budget(budget: int, typed, where: str) -> None:
    """A memory budget (bytes) no larger than this process can use (jaxexo.config.memory's
    ``process_memory_limit``): ConfigError naming ``where`` and the value as ``typed``."""
    from jaxexo.config.memory import process_memory_limit

    have, what = process_memory_limit()
    if have is not None and budget > have:
        raise ConfigError(
            f"{where}: {typed} is more memory than this process can use ({have / 2**30:.1f} GiB, "
            f"{what}); give at most {have // 2**20} MiB, or leave it out (half the available memory)"
        )


def local_cpu_count() -> int:
    return (
        len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    )


def param_count(cfg: Config) -> int:
    t = cfg.train
    obs_dim = _obs_dim(cfg.env.obs_mode, cfg.env.shape_points)
    sizes = [obs_dim, *t.hidden, NUM_ACTIONS]
    n = sum(a * b + b for a, b in zip(sizes[:-1], sizes[1:]))
    return n + (2 * sum(t.hidden) if t.layer_norm else 0)


def agent_bytes(cfg: Config) -> int:
    """Generous estimate of the memory one agent takes in a compiled chunk: its training state,
    rollout buffers, network activations, the environment step's temporaries, the per-update
    metrics and the greedy evaluation, times two for XLA's temporaries and the scan's carries."""
    t, e = cfg.train, cfg.env
    obs_dim = _obs_dim(e.obs_mode, e.shape_points)
    n_env, T = t.num_envs, t.rollout_steps
    k = max(cfg.outline_vertices, 16)  # the evaluation's outlines (the half-circle's 16 vertices)
    p = param_count(cfg)
    width = sum(t.hidden) + NUM_ACTIONS
    env_state = 2 * k + e.shape_points + 16 + obs_dim
    step = k * _STEP_FLOATS_PER_VERTEX + _STEP_FLOATS
    state = 4 * p + n_env * env_state + (n_env * p if t.trace == "backward" else 0)
    if t.trace == "forward":
        work = (
            T * n_env * (2 * obs_dim + 8 + NUM_ACTIONS)
            + 3 * (T * n_env // t.num_minibatches) * width
        )
    else:
        work = 3 * n_env * p + 2 * n_env * width
    work += n_env * (step + width)
    evaluation = t.eval_episodes * (env_state + step + width)
    floats = 2 * state + work + evaluation + 8 * num_updates(cfg) + 64 * 8
    return int(4 * floats * _SAFETY)


@dataclass(frozen=True)
class Chunk:
    chunk_id: int
    group_id: int
    size: int  # agents in the compiled batch (padded)
    agents: tuple[tuple[int, int], ...]  # (config_id, seed), the real ones

    def to_json(self) -> dict:
        d = asdict(self)
        d["agents"] = [list(a) for a in self.agents]
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Chunk":
        return cls(
            int(d["chunk_id"]),
            int(d["group_id"]),
            int(d["size"]),
            tuple((int(c), int(s)) for c, s in d["agents"]),
        )


def group_chunk_size(
    n_agents: int,
    per_agent_bytes: int,
    per_agent_steps: int,
    devices: int,
    budget: int,
    fixed: int | None = None,
) -> int:
    """Agents per chunk for a group: at most the memory cap and about the progress cap, a multiple of
    ``devices``; among the sizes from half that cap up to it, the one that pads the last chunk least
    (padding is computed and thrown away), the largest of those."""
    if fixed is not None:
        c = fixed
    else:
        c = min(budget // per_agent_bytes, max(1, round(CHUNK_ENV_STEPS / max(per_agent_steps, 1))))
    c = max(devices, (min(c, n_agents) // devices) * devices)
    if fixed is None and c * per_agent_bytes > budget:
        need = devices * per_agent_bytes
        raise ConfigError(
            f"memory_budget: {devices} agent(s) (one per CPU device) need about {need / 2**20:.0f} MiB, "
            f"more than the budget of {budget / 2**20:.0f} MiB; raise --memory-budget"
        )
    sizes = range(c, max(devices, c // 2) - 1, -devices)
    return min(sizes, key=lambda s: (math.ceil(n_agents / s) * s - n_agents, -s))


def make_plan(sweep: Sweep, devices: int, budget: int) -> list[Chunk]:
    """The chunks of every group, in order; chunk ids run over the whole sweep."""
    chunks: list[Chunk] = []
    for g in sweep.groups:
        cfg = sweep.members[g.config_ids[0]].config
        steps = num_updates(cfg) * cfg.train.num_envs * cfg.train.rollout_steps
        size = group_chunk_size(
            len(g.agents), agent_bytes(cfg), steps, devices, budget, sweep.chunk_size
        )
        for i in range(0, len(g.agents), size):
            chunks.append(Chunk(len(chunks), g.group_id, size, g.agents[i : i + size]))
    return chunks
