"""A sweep group's compiled program and the run of one chunk (JAX). ``chunk_program(cfg, devices)``
runs every agent's program (jaxexo.train.lanes.agent_program: the whole training scan, greedy
evaluation on the fixed test layouts, the divergence rule) in lanes over the CPU devices, reduced
inside the program to a few scalars, a learning curve and the final parameters; it is cached per
static settings, so every chunk of a group reuses one compilation. A diverged agent is flagged, the
others untouched (docs/training.md, Hyperparameter sweeps).
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization, struct

from jaxexo.config import Config, static_settings, test_config
from jaxexo.env import ExoStepEnv
from jaxexo.physics.scenarios import HELD_OUT, TEST_KINDS
from jaxexo.sweep.plan import Chunk
from jaxexo.sweep.results import SCALARS, ChunkResult
from jaxexo.sweep.spec import Sweep
from jaxexo.train.evaluate import make_rollouts, test_layouts
from jaxexo.train.lanes import agent_program, over_lanes, padded_agents
from jaxexo.train.trainer import METRICS, Hyperparams, Trainer, UpdateMetrics

CURVE_POINTS = 50
# Episodes to reach this training success rate (strict success, under the behaviour policy), over a
# trailing window of about 1 % of the updates that finished at least MIN_WINDOW_EPISODES episodes.
TARGET_SUCCESS = 0.9
MIN_WINDOW_EPISODES = 20
_PROGRAMS: dict = {}


@struct.dataclass
class TrainFigures:
    """An agent's training figures (``reduce_metrics``): scalars, and the curve [CURVE_POINTS]."""

    train_success: jnp.ndarray  # strict success per episode over the last active updates
    train_return: jnp.ndarray  # undiscounted return per episode over them
    episodes_to_90: jnp.ndarray  # episodes until TARGET_SUCCESS (nan: never)
    updates: jnp.ndarray  # the active updates
    curve: UpdateMetrics  # [CURVE_POINTS], each bin a sum


def reduce_metrics(m: UpdateMetrics, min_episodes: int) -> TrainFigures:
    """Per-update metrics [U] -> the agent's training figures and its learning curve (UpdateMetrics
    [CURVE_POINTS], each bin a sum).
    The active updates (before the budget ran out) are a prefix of the scan. The final training
    figures cover the last tenth of the active updates, widened backwards until at least
    ``min_episodes`` episodes finished in it (nan if none did)."""
    n_upd, col = m.episodes.shape[0], m
    idx = jnp.arange(n_upd)
    n_active = jnp.sum(col.env_steps > 0)
    ep = col.episodes
    after = jnp.cumsum(ep[::-1])[::-1] - ep  # episodes finished after each update
    last = (idx < n_active) & (
        (idx >= n_active - jnp.maximum(1, n_active // 10)) | (after < min_episodes)
    )
    ep_last = jnp.sum(jnp.where(last, ep, 0.0))
    per_episode = lambda x: jnp.where(  # noqa: E731
        ep_last > 0, jnp.sum(jnp.where(last, x, 0.0)) / jnp.maximum(ep_last, 1.0), jnp.nan
    )
    train_success, train_return = per_episode(col.successes), per_episode(col.return_sum)
    # Episodes to reach TARGET_SUCCESS: the first update whose trailing window (about 1 % of the
    # updates) succeeds that often; the count is of all episodes finished up to that update.
    window = max(1, n_upd // 100)
    cum_ep = jnp.cumsum(col.episodes)
    cum_su = jnp.cumsum(col.successes)
    shift = (  # noqa: E731
        lambda x: (
            jnp.concatenate([jnp.zeros(window), x[:-window]])
            if window < n_upd
            else jnp.zeros_like(x)
        )
    )
    ep_w, su_w = cum_ep - shift(cum_ep), cum_su - shift(cum_su)
    hit = (ep_w >= MIN_WINDOW_EPISODES) & (su_w >= TARGET_SUCCESS * ep_w)
    episodes_to = jnp.where(jnp.any(hit), cum_ep[jnp.argmax(hit)], jnp.nan)
    bins = np.minimum(np.arange(n_upd) * CURVE_POINTS // n_upd, CURVE_POINTS - 1)
    curve = jax.tree.map(
        lambda x: jax.ops.segment_sum(x, jnp.asarray(bins), num_segments=CURVE_POINTS), m
    )
    return TrainFigures(
        train_success=train_success,
        train_return=train_return,
        episodes_to_90=episodes_to,
        updates=n_active.astype(jnp.float32),
        curve=curve,
    )


def chunk_program(cfg: Config, devices):
    """The compiled chunk program for cfg's static settings on ``devices`` (cached)."""
    key = (static_settings(cfg), tuple(str(d) for d in devices))
    if key not in _PROGRAMS:
        _PROGRAMS[key] = _build(cfg, list(devices))
    return _PROGRAMS[key]


def _build(cfg: Config, devices):
    trainer = Trainer(cfg)
    tcfg = test_config(cfg)
    tenv = ExoStepEnv(tcfg)
    run = agent_program(
        trainer, make_rollouts(tenv, trainer.net.apply, tcfg.env.max_steps), trainer.num_updates
    )
    n_eval = cfg.train.eval_episodes
    kinds = np.arange(n_eval) % len(TEST_KINDS)
    held = jnp.asarray(np.isin(np.asarray(TEST_KINDS)[kinds], HELD_OUT), jnp.float32)

    def agent(key, hyper, test):
        test_params, test_lay = test
        ts, m, out, ok = run(trainer.init(key, hyper), hyper, test_lay, test_params)
        suc, acc = out.success.astype(jnp.float32), out.accurate.astype(jnp.float32)
        red = reduce_metrics(m, cfg.train.num_envs)
        scalars = {
            "success": suc.mean(),
            "accuracy": acc.mean(),
            "held_out_success": jnp.sum(suc * held) / held.sum(),
            "held_out_accuracy": jnp.sum(acc * held) / held.sum(),
            "eval_return": out.episode_return.mean(),
            "episodes": ts.episodes,
            "env_steps": ts.update,  # updates done: run_chunk scales it to env steps in integers
            "diverged": ~ok,
            "train_success": red.train_success,
            "train_return": red.train_return,
            "episodes_to_90": red.episodes_to_90,
            "updates": red.updates,
        }
        return {"scalars": scalars, "curve": red.curve, "params": ts.params}

    return over_lanes(agent, devices, n_args=3)


def _stack(trees):
    return jax.tree.map(lambda *x: np.stack([np.asarray(v) for v in x]), *trees)


def chunk_inputs(sweep: Sweep, chunk: Chunk, size: int | None = None):
    """Keys, Hyperparams and test-environment (params, layouts) of the chunk's agents, padded to ``size``
    (default: the chunk's) with copies of the first agent."""
    agents = list(chunk.agents) + [chunk.agents[0]] * ((size or chunk.size) - len(chunk.agents))
    cfgs = {c: sweep.members[c].config for c in {c for c, _ in agents}}
    hyper = {c: Hyperparams.from_config(cfg) for c, cfg in cfgs.items()}
    # The test layouts drawn in NumPy (jaxexo.train.evaluate.test_layouts): eval.json's and
    # ``jaxexo eval``'s scenes.
    test = {
        c: (
            ExoStepEnv(test_config(cfg)).default_params,
            test_layouts(test_config(cfg), cfg.train.eval_episodes),
        )
        for c, cfg in cfgs.items()
    }
    keys = np.stack([np.asarray(jax.random.PRNGKey(s)) for _, s in agents])
    return keys, _stack([hyper[c] for c, _ in agents]), _stack([test[c] for c, _ in agents])


def run_chunk(sweep: Sweep, chunk: Chunk, devices=None) -> ChunkResult:
    """Train and evaluate one chunk: its real agents' results."""
    devices = list(devices if devices is not None else jax.local_devices())
    if chunk.size % len(devices):
        raise ValueError(
            f"chunk {chunk.chunk_id}: {chunk.size} agents do not split over {len(devices)} devices"
        )
    cfg = sweep.members[chunk.agents[0][0]].config
    t0 = time.perf_counter()
    program = chunk_program(cfg, devices)
    # Whole blocks of LANES agents on every device (over_lanes): a plan's chunk may need more padding.
    size = max(chunk.size, padded_agents(chunk.size, len(devices)))
    out = jax.block_until_ready(program(*chunk_inputs(sweep, chunk, size)))
    wall = time.perf_counter() - t0
    n = len(chunk.agents)
    per = cfg.train.num_envs * cfg.train.rollout_steps
    out = jax.tree.map(lambda x: np.asarray(x)[:n], out)
    flat = serialization.to_state_dict(out["params"])
    return ChunkResult(
        chunk_id=chunk.chunk_id,
        agents=[list(a) for a in chunk.agents],
        scalars={
            k: (
                out["scalars"][k].astype(np.int64) * per if k == "env_steps" else out["scalars"][k]
            ).astype(np.float64)
            for k in SCALARS
        },
        # The chunk file's curves: columns in METRICS order.
        curves=np.stack([getattr(out["curve"], k) for k in METRICS], axis=-1),
        metrics=list(METRICS),
        params=_flatten(flat),
        wall_s=wall,
    )


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}/"))
        else:
            out[f"{prefix}{k}"] = np.asarray(v)
    return out


def unflatten(flat: dict, index: int) -> dict:
    """One agent's parameter tree from ``run_chunk``'s flattened params (or the saved chunk file)."""
    tree: dict = {}
    for path, v in flat.items():
        node = tree
        *parents, leaf = path.split("/")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = np.asarray(v)[index]
    return tree
