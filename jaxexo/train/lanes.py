"""One agent's program (train, greedy rollouts, the divergence rule) and many agents run as one
compiled program (JAX), every device running its agents in fixed blocks of LANES so that an agent's
arithmetic never depends on who else is in the program (why: docs/training.md, Group-size
independence; tests/test_population.py checks it bit for bit).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

# Agents per vmapped block: fixed, so that an agent's arithmetic never depends on how many agents
# share its program. Two buys most of the batching gain while a lone member (a population of one, a
# sweep's last odd agent) pays for one padding lane, not three (measured: docs/training.md).
LANES = 2


def finite(xp, ts, metrics):
    """The one divergence rule: a chunk diverged unless its parameters, target parameters and metrics
    (the loss among them) are all finite. ``xp``: numpy on the host, jax.numpy inside a compiled
    program (a population's or a sweep's, per agent)."""
    leaves = jax.tree.leaves((ts.params, ts.target_params, metrics))
    return xp.all(xp.stack([xp.all(xp.isfinite(x)) for x in leaves]))


def agent_program(trainer, rollouts, n_updates: int):
    """The one agent program of populations and sweeps: ``agent(ts, hyper, layouts, env_params)`` runs
    ``n_updates`` updates of ``trainer`` from ``ts``, then the greedy ``rollouts``
    (jaxexo.train.evaluate.make_rollouts) of the new parameters on ``layouts`` [N]; returns the state,
    the UpdateMetrics [n_updates], the rollouts' per-episode outcomes [N] and ``finite``."""

    def agent(ts, hyper, layouts, env_params):
        ts, m = trainer.run(ts, hyper, n_updates)
        return ts, m, rollouts(ts.params, layouts, env_params), finite(jnp, ts, m)

    return agent


def over_agents(fn, devices, n_args: int):
    """``jit(shard_map(vmap(fn)))``: every argument and output has a leading agent axis, split evenly
    over ``devices`` (each device runs its share of the agents as one vmapped batch). An agent's
    arithmetic depends on that batch's size: throughput benchmarks only; training uses ``over_lanes``."""
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    spec = P("agents")
    return jax.jit(
        jax.shard_map(
            jax.vmap(fn),
            mesh=Mesh(np.array(list(devices)), ("agents",)),
            in_specs=(spec,) * n_args,
            out_specs=spec,
            check_vma=False,
        )
    )


def padded_agents(n_agents: int, n_devices: int, lanes: int = LANES) -> int:
    """The agent count ``over_lanes`` runs for ``n_agents`` on ``n_devices``: the next multiple of
    devices x lanes (the extra agents are padding)."""
    unit = n_devices * lanes
    return -(-n_agents // unit) * unit


def over_lanes(fn, devices, n_args: int, shared: int = 0, lanes: int = LANES):
    """``jit(shard_map(lax.map(vmap(fn))))``: like ``over_agents``, but each device runs its share of
    the agents ``lanes`` at a time (``lax.map`` over blocks of ``vmap(fn)`` of exactly ``lanes``
    agents), so that an agent's arithmetic does not depend on how many agents the program holds (the
    module doc). The first ``n_args`` arguments have a leading agent axis of a multiple of
    len(devices) x lanes (``padded_agents``); the ``shared`` arguments after them are the same for
    every agent (replicated, not batched)."""
    from jax.sharding import Mesh
    from jax.sharding import PartitionSpec as P

    def local(*args):
        batched, common = args[:n_args], args[n_args:]
        n = jax.tree.leaves(batched)[0].shape[0]
        if n % lanes:
            raise ValueError(
                f"over_lanes: {n} agents per device is not a multiple of {lanes} lanes"
            )
        blocks = jax.tree.map(lambda x: x.reshape((n // lanes, lanes) + x.shape[1:]), batched)
        block = jax.vmap(lambda *b: fn(*b, *common))
        out = jax.lax.map(lambda b: block(*b), blocks)
        return jax.tree.map(lambda x: x.reshape((n,) + x.shape[2:]), out)

    # Compilation events name the program by this function: keep the agent function's name in it.
    local.__name__ = f"{getattr(fn, '__name__', 'fn')}_in_lanes"
    spec = P("agents")
    return jax.jit(
        jax.shard_map(
            local,
            mesh=Mesh(np.array(list(devices)), ("agents",)),
            in_specs=(spec,) * n_args + (P(),) * shared,
            out_specs=spec,
            check_vma=False,
        )
    )
