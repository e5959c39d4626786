"""Environment throughput benchmark: env-steps/s with random actions and the full reward.

The whole rollout is one compiled ``lax.scan`` over ``env.step_batch`` (the trainer's step:
``jax.vmap(env.step)``'s transitions, fresh scenes drawn only where an episode ended); the scan carries a
reduced metric (the summed reward) so nothing per-step is stacked and nothing is dead-code
eliminated. Times are medians over repeats, after a warm-up call that compiles.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from jaxexo.config import EQUAL_WEIGHTS, THESIS_JOINT_LIMITS, Config
from jaxexo.env import ExoStepEnv
from jaxexo.physics.geometry import THESIS_OBSTACLES
from jaxexo.summary import Summary, table


def make_rollout(env: ExoStepEnv, num_envs: int, num_steps: int, devices=None, mask: str = "none"):
    """Compiled random-action rollout of ``num_envs`` environments for ``num_steps`` steps, the batch
    split evenly over ``devices`` (default: every local device that divides it). ``mask``: "none"
    (any move), or the shield's mask computed every step as the trainer does, the action drawn among
    the admissible moves: "plain" (``vmap(env.action_mask)``, every move checked exactly) or
    "batched" (``env.action_masks``, the trainer's: bounds, then the exact check where they leave it open)."""
    devices = devices or jax.local_devices()
    d = len(devices)
    while num_envs % d:
        d -= 1
    devices = devices[:d]
    per_device = num_envs // d

    def rollout(key, params):
        return _rollout(env, per_device, num_steps, key[0], params, mask)[None]

    mesh = Mesh(np.array(devices), ("envs",))
    sharded = jax.shard_map(
        rollout, mesh=mesh, in_specs=(P("envs"), P()), out_specs=P("envs"), check_vma=False
    )

    def run(key, params):
        return sharded(jax.random.split(key, d), params).sum(axis=0)

    return jax.jit(run), d


def _mask_fn(env, mask):
    if mask == "plain":
        return jax.vmap(env.action_mask, in_axes=(0, None))
    if mask == "batched":
        return env.action_masks
    return None


def _rollout(env, num_envs, num_steps, key, params, mask="none"):
    k0, key = jax.random.split(key)
    _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k0, num_envs), params)
    masks = _mask_fn(env, mask)

    def body(carry, _):
        state, key, acc = carry
        key, ka, ks = jax.random.split(key, 3)
        if masks is None:
            actions = jax.random.randint(ka, (num_envs,), 0, env.num_actions)
        else:  # uniform over the admissible moves of the current state (the trainer's exploration)
            actions = jax.random.categorical(
                ka, jnp.where(masks(state, params), 0.0, -jnp.inf), axis=-1
            )
        _, state, out, _ = env.step_batch(jax.random.split(ks, num_envs), state, actions, params)
        acc = acc + jnp.stack([out.reward.sum(), out.terminated.sum(), out.info.collision.sum()])
        return (state, key, acc), None

    (state, _, acc), _ = jax.lax.scan(body, (state, key, jnp.zeros(3)), None, length=num_steps)
    return acc


def bench_env(
    num_envs_list=(1, 256, 4096, 16384),
    steps_per_call=None,
    repeats=5,
    config=None,
    progress=print,
    mask: str = "none",
) -> list[dict]:
    """Measure env-steps/s for each batch size; returns one row per size (``mask``: make_rollout's)."""
    env = ExoStepEnv(config or Config())
    params = env.default_params
    rows = []
    for n in num_envs_list:
        steps = steps_per_call or max(50, min(2000, 2_000_000 // n))
        fn, ndev = make_rollout(env, n, steps, mask=mask)
        key = jax.random.PRNGKey(0)
        t0 = time.perf_counter()
        jax.block_until_ready(fn(key, params))
        compile_s = time.perf_counter() - t0
        times = []
        for r in range(repeats):
            t0 = time.perf_counter()
            out = jax.block_until_ready(fn(jax.random.PRNGKey(r + 1), params))
            times.append(time.perf_counter() - t0)
        med = Summary.of(times).median
        row = {
            "num_envs": n,
            "steps_per_call": steps,
            "median_s": med,
            "env_steps_per_s": n * steps / med,
            "compile_s": compile_s,
            "devices": ndev,
            "episodes_finished": float(out[1]),
            "mask": mask,
        }
        progress(
            f"  {n:>6} envs: {row['env_steps_per_s'] / 1e6:8.3f} M env-steps/s "
            f"(median of {repeats}, {steps} steps/call, {ndev} device(s), compile {compile_s:.1f} s)"
        )
        rows.append(row)
    return rows


# The thesis's five obstacles (Table 3.1) and a rectangle range.
MIXED_KINDS = [
    *THESIS_OBSTACLES,
    {"kind": "rectangle", "width": [0.05, 0.20], "height": [0.05, 0.20]},
]


def mixed_config() -> Config:
    """Every obstacle kind in one batch (outline size K = 16, the half-circle's), all pivots."""
    from jaxexo.config import config_from_dict

    # Stated in full (the env-step settings of the recorded results): unshielded, obstacle mixture, no
    # placement jitter, thesis-like reward weights; a field left out would take the default model's value.
    return config_from_dict(
        {
            "env": {"shield": False, "obs_profile": "bbox"},
            "kinematics": dict(THESIS_JOINT_LIMITS),
            "reward": {
                **EQUAL_WEIGHTS,
                "goal_reward": 10.0,
                "joint_limit_penalty": 1.0,
                "progress_shaping": 0.0,
            },
            "layout": {
                "obstacles": MIXED_KINDS,
                "pivot": ["agent", "obstacle", "between"],
                "terrain": False,
                "obstacle_offset": [0.0, 0.0],
                "start_shift": [0.0, 0.0],
                "step_length": [0.70, 0.70],
            },
        }
    )


def run_env_benchmark(
    config: Config,
    config_name: str,
    sizes,
    out_dir,
    progress=print,
    name: str = "env",
    mixed: bool = True,
) -> dict:
    """Benchmark the given config and, for comparison, the all-kinds mix; write the results. A
    shielded config is also measured with the shield's mask computed every step, as the trainer
    does: the plain rule and the trainer's batched one, back to back."""
    from jaxexo.evaluation.machine import write_result

    results = {}
    runs = [(config_name, config, "none")]
    if config.env.shield:
        runs += [
            (f"{config_name} + mask (plain)", config, "plain"),
            (f"{config_name} + mask (batched)", config, "batched"),
        ]
    if mixed:
        runs.append(("all obstacle kinds (K=16)", mixed_config(), "none"))
    for label, cfg, mask in runs:
        progress(f"{label}: outline size K = {cfg.outline_vertices}, obs_mode = {cfg.env.obs_mode}")
        results[label] = bench_env(sizes, config=cfg, progress=progress, mask=mask)
    lines = [
        "# Environment throughput (random actions, full reward, auto-reset)",
        "",
        *table(
            ("layout", "envs", "devices", "M env-steps/s"),
            [
                (label, r["num_envs"], r["devices"], f"{r['env_steps_per_s'] / 1e6:.2f}")
                for label, rows in results.items()
                for r in rows
            ],
        ),
    ]
    lines.append("")
    lines.append(
        "Shared machine: other jobs ran at the same time, so figures are noisy; rows of one file were "
        "measured back to back in one process."
    )
    paths = write_result(name, {"results": results}, "\n".join(lines), out_dir)
    progress("\n".join(lines))
    progress(f"wrote {paths[0]} and {paths[1]}")
    return results
