"""Greedy evaluation of a Q-network on fixed test layouts (thesis 2.6, 3.3; eq 3.1): the scenes of
``jaxexo eval --scenarios test``, per episode ``accurate`` and the strict ``success``. What it reports:
docs/training.md, "``jaxexo train`` and what a run writes" (eval.json).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from jaxexo.config import Config, numpy_params, test_config
from jaxexo.env import ExoStepEnv
from jaxexo.env.exo_step import Layout
from jaxexo.physics import actions, outcome, scenarios
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics.scenarios import HELD_OUT, TEST_KINDS  # noqa: F401 (one definition, re-exported)


def layout_set(cfg: Config, n: int, seed: int, cycle: bool = False) -> Layout:
    """The n layouts of scenario set ``seed`` (jaxexo.physics.scenarios.scenario_layouts), as NumPy
    arrays in a Layout. Drawn in NumPy and fed to JAX, so that they are bit for bit the scenes
    jaxexo.inference.scenarios gives NumPy tools (under jit, XLA fuses multiply-adds, which would
    move a size by an ulp); ``cycle``: kinds and pivot conditions in turn (a test set)."""
    return Layout(**scenarios.scenario_layouts(np, numpy_params(cfg), seed, n, cycle)._asdict())


def test_layouts(tcfg: Config, n: int, seed: int = 12345) -> Layout:
    """The n layouts of the test set ``seed`` for ``tcfg = test_config(cfg)``: kinds and pivots cycle
    evenly (every kind x pivot pair equally often), the rest drawn from the distribution; the scenes
    of jaxexo.inference.scenarios.sample_scenarios(cfg, n, seed)."""
    return layout_set(tcfg, n, seed, cycle=True)


@struct.dataclass
class Rollouts:
    """Greedy episodes' outcomes, each field [N] (one episode: no axis)."""

    steps: jnp.ndarray  # steps taken
    episode_return: jnp.ndarray  # the undiscounted return
    reached: jnp.ndarray  # the goal was reached
    collided: jnp.ndarray  # the foot touched the obstacle
    limits: jnp.ndarray  # a joint limit was violated
    leg: jnp.ndarray  # a leg was too long
    min_clearance: jnp.ndarray  # m, the smallest clearance of the foot's motion
    accurate: jnp.ndarray  # eq 3.1: never touched
    success: jnp.ndarray  # the strict verdict (jaxexo.physics.outcome)


def make_rollouts(env: ExoStepEnv, q_apply, max_steps: int, record: bool = False):
    """Greedy rollouts of a batch of layouts: ``rollouts(q_params, layouts, params)`` with layout
    fields of leading axis N returns per-episode outcomes (N,) (and the heel paths (N, max_steps, 2) if
    ``record``), as ``jax.vmap`` of one layout's rollout would. The shield's mask is computed for the
    whole batch at once (``env.action_masks``: ``action_mask``'s decisions, the exact swept check only
    for the moves its bounds leave open), cheaper per step than one layout's mask vmapped
    (docs/training.md)."""

    def rollouts(q_params, layouts, params):
        obs, state = jax.vmap(env.init_state, in_axes=(0, None))(layouts, params)
        n = obs.shape[0]

        def rows(alive, x):  # alive (N,) against a leaf with leading axis N
            return alive.reshape(alive.shape + (1,) * (x.ndim - 1))

        def step(carry, _):
            state, obs, alive, out = carry
            # greedy over the admissible moves (all of them without the shield)
            mask = env.action_masks(state, params) if env.shield else None
            a = actions.greedy_action(jnp, q_apply(q_params, obs), mask)
            obs2, state2, s = jax.vmap(env.advance, in_axes=(0, 0, None))(state, a, params)
            acc, steps, ret = out
            out = (
                outcome.accumulate(jnp, acc, s.info, alive),
                steps + alive,
                ret + jnp.where(alive, s.reward, 0.0),
            )
            state = jax.tree.map(
                lambda new, old: jnp.where(rows(alive, new), new, old), state2, state
            )
            obs = jnp.where(alive[:, None], obs2, obs)
            alive = alive & ~s.terminated & ~s.truncated
            return (state, obs, alive, out), (state.heel if record else None)

        # (running outcome, steps, return) of each episode
        out0 = (outcome.start(jnp, (n,)), jnp.zeros(n, jnp.int32), jnp.zeros(n, jnp.float32))
        (_, _, _, (acc, steps, ret)), path = jax.lax.scan(
            step, (state, obs, jnp.ones(n, bool), out0), None, length=max_steps
        )
        v = outcome.episode_verdict(jnp, acc, **outcome.rule(params))
        out = Rollouts(
            steps=steps,
            episode_return=ret,
            reached=acc.reached_goal,
            collided=~v.collision_free,
            limits=acc.limits,
            leg=acc.leg,
            min_clearance=acc.min_clearance,
            accurate=v.collision_free,
            success=v.success,
        )
        return (out, jnp.swapaxes(path, 0, 1)) if record else out

    return rollouts


def make_rollout(env: ExoStepEnv, q_apply, max_steps: int, record: bool = False):
    """Greedy rollout of one layout (``make_rollouts`` of a batch of one): per-episode outcomes (and
    the heel path (max_steps, 2) if ``record``)."""
    rollouts = make_rollouts(env, q_apply, max_steps, record)

    def rollout(q_params, layout, params):
        res = rollouts(q_params, jax.tree.map(lambda x: jnp.asarray(x)[None], layout), params)
        return jax.tree.map(lambda x: x[0], res)

    return rollout


def summarize(out: Rollouts, kinds: np.ndarray, pivots: np.ndarray, kind_names=TEST_KINDS) -> dict:
    """eval.json's figures: overall, by obstacle kind and by pivot condition."""
    acc = np.asarray(out.accurate, bool)
    suc = np.asarray(out.success, bool)

    def fig(mask):
        return {
            "accuracy": float(acc[mask].mean()),
            "success_raw": float(suc[mask].mean()),
            "n": int(mask.sum()),
        }

    held = np.isin(np.asarray(kind_names)[kinds], HELD_OUT)
    return {
        "accuracy": float(acc.mean()),
        # On the agent's raw greedy moves in the environment (no smoothing); ``jaxexo eval`` reports
        # ``success`` of the final smoothed trajectories on the same scenes.
        "success_raw": float(suc.mean()),
        "success": float(suc.mean()),  # old name of success_raw, kept for existing readers
        "held_out": fig(held) if held.any() else None,
        "by_obstacle": {k: fig(kinds == i) for i, k in enumerate(kind_names) if (kinds == i).any()},
        "by_pivot": {
            p: fig(pivots == i) for i, p in enumerate(PIVOT_CONDITIONS) if (pivots == i).any()
        },
        "mean_steps": float(np.mean(out.steps)),
        "reached_goal": float(np.mean(out.reached)),
    }


def make_evaluator(cfg: Config, net, n: int = 1000, seed: int = 12345):
    """``evaluate`` for many parameter sets of one network: one compiled program, called per set
    (a population's members are scored one by one, so that each member's figures come from the same
    program whatever the population's size)."""
    tcfg = test_config(cfg)
    env = ExoStepEnv(tcfg)
    params = env.default_params
    layouts = test_layouts(tcfg, n, seed)
    run = jax.jit(make_rollouts(env, net.apply, tcfg.env.max_steps))

    def evaluate_params(q_params) -> dict:
        out = jax.tree.map(np.asarray, run(q_params, layouts, params))
        return summarize(out, np.asarray(layouts.kind), np.asarray(layouts.pivot_kind))

    return evaluate_params


def evaluate(cfg: Config, net, q_params, n: int = 1000, seed: int = 12345) -> dict:
    """Greedy rollouts of the Q-network on n test layouts; returns the eval.json figures."""
    return make_evaluator(cfg, net, n, seed)(q_params)


VALIDATION_EPISODES, VALIDATION_SEED = 500, 777


def validation_set(cfg: Config, n: int = VALIDATION_EPISODES, seed: int = VALIDATION_SEED):
    """(env, env params, layouts) of the validation scenes: n layouts drawn from the *training*
    distribution (never the held-out test obstacles)."""
    env = ExoStepEnv(cfg)
    return env, env.default_params, layout_set(cfg, n, seed)


def make_validator(cfg: Config, net, n: int = VALIDATION_EPISODES, seed: int = VALIDATION_SEED):
    """Greedy strict success on n layouts drawn from the *training* distribution (never the held-out
    test obstacles), for choosing which parameters to export. Returns ``validate(q_params) -> float``."""
    env, params, layouts = validation_set(cfg, n, seed)
    rollout = make_rollouts(env, net.apply, cfg.env.max_steps)

    @jax.jit
    def validate(q_params):
        return jnp.mean(rollout(q_params, layouts, params).success)

    return lambda q_params: float(validate(q_params))
