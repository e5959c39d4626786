"""Greedy evaluation of a Q-network on fixed test layouts (thesis 2.6, 3.3; eq 3.1).

The test set mixes the five thesis obstacles (Table 3.1: Base 1-3 seen in training, triangle and
half-circle held out) with the three pivot conditions, jittered like the training layouts, from a
fixed key so that every model is scored on the same scenes. Rollouts are greedy and deterministic
(thesis-notes: a generator for a device must not explore), with no auto-reset: an episode ends at
the goal, at a collision when collisions terminate, or at the step limit.

Per episode: ``accurate`` (eq 3.1: the foot never entered the obstacle), ``success`` (strict: the
goal was reached, the heel-toe segment never touched the obstacle, joint limits and leg length were
respected throughout).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from jaxexo.config import PIVOT_CONDITIONS, Config, named_spec
from jaxexo.env import ExoStepEnv
from jaxexo.inference.scenarios import HELD_OUT, TEST_KINDS  # noqa: F401 (one definition, re-exported)


def test_config(cfg: Config) -> Config:
    """The training config with the layout's obstacle mixture replaced by the five thesis obstacles
    and all three pivot conditions (same jitter, start shifts and step lengths)."""
    lay = dataclasses.replace(cfg.layout, obstacles=tuple(named_spec(k) for k in TEST_KINDS),
                              pivot=(1.0, 1.0, 1.0))
    env = dataclasses.replace(cfg.env, max_vertices=0)
    return dataclasses.replace(cfg, layout=lay, env=env)


def test_layouts(env: ExoStepEnv, params, n: int, seed: int = 12345):
    """n layouts: kinds and pivots cycle evenly (every kind x pivot pair equally often), the rest of
    the layout (size jitter, position, start shift, step length) drawn from the distribution."""
    idx = np.arange(n)
    kinds = idx % len(TEST_KINDS)
    pivots = (idx // len(TEST_KINDS)) % len(PIVOT_CONDITIONS)
    # Re-sample with the chosen kind and pivot: a one-kind, one-pivot distribution per episode.
    one_hot_cdf = lambda k, m: jnp.where(jnp.arange(m)[None, :] >= k[:, None], 1.0, 0.0)  # noqa: E731
    per = params.replace(kind_cdf=one_hot_cdf(jnp.asarray(kinds), len(TEST_KINDS)),
                         pivot_cdf=one_hot_cdf(jnp.asarray(pivots), 3))
    axes = jax.tree.map(lambda _: None, params).replace(kind_cdf=0, pivot_cdf=0)
    return jax.vmap(env.sample_layout, in_axes=(0, axes))(jax.random.split(jax.random.PRNGKey(seed), n), per)


def make_rollout(env: ExoStepEnv, q_apply, max_steps: int, record: bool = False):
    """Greedy rollout of one layout: returns per-episode outcomes (and the heel path if ``record``)."""

    def rollout(q_params, layout, params):
        obs, state = env.init_state(layout, params)

        def step(carry, _):
            state, obs, alive, out = carry
            a = jnp.argmax(q_apply(q_params, obs))
            obs2, state2, r, term, info = env.step_env(jax.random.PRNGKey(0), state, a, params)
            truncated = env.is_truncated(state2, params)
            out = {
                "reached": out["reached"] | (alive & info["goal_reached"]),
                "collided": out["collided"] | (alive & info["collision"]),
                "limits": out["limits"] | (alive & info["joint_limit_violation"]),
                "leg": out["leg"] | (alive & info["leg_length_violation"]),
                "unsafe": out["unsafe"] | (alive & info["unsafe"]),
                "steps": out["steps"] + alive,
                "return": out["return"] + jnp.where(alive, r, 0.0),
                "min_clearance": jnp.where(alive, jnp.minimum(out["min_clearance"], info["clearance"]), out["min_clearance"]),
            }
            state = jax.tree.map(lambda n, o: jnp.where(alive, n, o), state2, state)
            obs = jnp.where(alive, obs2, obs)
            alive = alive & ~term & ~truncated
            return (state, obs, alive, out), (state.heel if record else None)

        out0 = {"reached": False, "collided": False, "limits": False, "leg": False, "unsafe": False,
                "steps": jnp.asarray(0), "return": jnp.asarray(0.0), "min_clearance": jnp.asarray(jnp.inf)}
        (_, _, _, out), path = jax.lax.scan(step, (state, obs, jnp.asarray(True), out0), None, length=max_steps)
        out["accurate"] = ~out["collided"]
        out["success"] = out["reached"] & ~out["collided"] & ~out["limits"] & ~out["leg"] & ~out["unsafe"]
        return (out, path) if record else out

    return rollout


def summarize(out: dict, kinds: np.ndarray, pivots: np.ndarray, kind_names=TEST_KINDS) -> dict:
    """eval.json's figures: overall, by obstacle kind and by pivot condition."""
    acc = np.asarray(out["accurate"], bool)
    suc = np.asarray(out["success"], bool)

    def fig(mask):
        return {"accuracy": float(acc[mask].mean()), "success": float(suc[mask].mean()), "n": int(mask.sum())}

    held = np.isin(np.asarray(kind_names)[kinds], HELD_OUT)
    return {
        "accuracy": float(acc.mean()),
        "success": float(suc.mean()),
        "held_out": fig(held) if held.any() else None,
        "by_obstacle": {k: fig(kinds == i) for i, k in enumerate(kind_names) if (kinds == i).any()},
        "by_pivot": {p: fig(pivots == i) for i, p in enumerate(PIVOT_CONDITIONS) if (pivots == i).any()},
        "mean_steps": float(np.mean(out["steps"])),
        "reached_goal": float(np.mean(out["reached"])),
    }


def evaluate(cfg: Config, net, q_params, n: int = 1000, seed: int = 12345) -> dict:
    """Greedy rollouts of the Q-network on n test layouts; returns the eval.json figures."""
    tcfg = test_config(cfg)
    env = ExoStepEnv(tcfg)
    params = env.default_params
    layouts = test_layouts(env, params, n, seed)
    rollout = make_rollout(env, net.apply, tcfg.env.max_steps)
    out = jax.jit(jax.vmap(rollout, in_axes=(None, 0, None)))(q_params, layouts, params)
    out = jax.tree.map(np.asarray, out)
    return summarize(out, np.asarray(layouts.kind), np.asarray(layouts.pivot_kind))


def make_validator(cfg: Config, net, n: int = 500, seed: int = 777):
    """Greedy strict success on n layouts drawn from the *training* distribution (never the held-out
    test obstacles), for choosing which parameters to export. Returns ``validate(q_params) -> float``."""
    env = ExoStepEnv(cfg)
    params = env.default_params
    layouts = jax.vmap(env.sample_layout, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(seed), n), params)
    rollout = jax.vmap(make_rollout(env, net.apply, cfg.env.max_steps), in_axes=(None, 0, None))

    @jax.jit
    def validate(q_params):
        return jnp.mean(rollout(q_params, layouts, params)["success"])

    return lambda q_params: float(validate(q_params))
