"""Training with obstacle changes ([env] obstacle_change): policies trained with and without it, side by
side on (a) the hidden safety sets, RL alone (the swing-quality figures: safe %, lift and timed duration
medians), and (b) mid-swing continuation in the environment: greedy episodes whose obstacle changes at
15-45 % of the swing (taller by 30-60 %, moved 3-5 cm farther, wider by 30-60 %, or a second obstacle),
success from the change = reaching the goal without coming within env.min_clearance of the new
obstacle. Run by benchmarks/bench_obstacle_change.py; method and numbers: docs/replanning.md.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any, NamedTuple

import numpy as np

from jaxexo.evaluation.machine import machine_info, write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics import changes, geometry, outcome
from jaxexo.summary import table
from jaxexo.train.evaluate import layout_set

from benchlib.swing_quality_bench import run_set, scene_sets

# The changes of (b): the [env] obstacle_change ranges of each (chance 1), the tallest obstacle
# allowed (m) not capped at the training's so that "taller" means 30-60 % taller.
CHANGES = {
    "taller 30-60 %": {"change_taller": (0.3, 0.6)},
    "moved 3-5 cm": {"change_move": (0.03, 0.05)},
    "wider 30-60 %": {"change_wider": (0.3, 0.6)},
    "second obstacle": {"change_second": 1.0},
}
AT_FRACTION = (0.15, 0.45)  # of the swing's steps (the policy trained without, unchanged scene)
SCENE_SEED = 4242  # the (b) layouts: the training distribution, a set neither training nor its
# validation draws


def _network(policy):
    """(net, params): the flax QNetwork of a policy file's layers and its parameters."""
    import jax.numpy as jnp

    from jaxexo.train.network import QNetwork

    hidden = tuple(int(k.shape[1]) for k in policy.kernels[:-1])
    net = QNetwork(hidden=hidden, layer_norm=bool(policy.norm_scales))
    layers = zip(policy.kernels[:-1], policy.biases[:-1])
    p = {f"dense_{i}": {"kernel": k, "bias": b} for i, (k, b) in enumerate(layers)}
    p["out"] = {"kernel": policy.kernels[-1], "bias": policy.biases[-1]}
    for i, (s, b) in enumerate(zip(policy.norm_scales, policy.norm_biases)):
        p[f"norm_{i}"] = {"scale": s, "bias": b}
    return net, {"params": {k: {n: jnp.asarray(v) for n, v in d.items()} for k, d in p.items()}}


class Episodes(NamedTuple):
    """Greedy episodes' outcomes, each [N]: steps, goal reached, the obstacle switched, the smallest
    clearance after the switch (m; inf without one), the heel's highest point after it above the new
    obstacle's top (m), a joint limit violated, the strict verdict of the whole episode."""

    steps: Any
    reached: Any
    fired: Any
    post_clearance: Any
    post_lift: Any
    limits: Any
    success: Any


def _greedy(env, net, max_steps: int):
    """``run(q_params, layouts, change, params)``: the ``Episodes`` of greedy episodes (N) from the
    layouts with their changes, the policy's moves inside the shield's mask when the config has it."""
    import jax
    import jax.numpy as jnp

    from jaxexo.physics import actions

    def run(q_params, layouts, change, params):
        obs, state = jax.vmap(env.init_state, in_axes=(0, None, 0))(layouts, params, change)
        n = obs.shape[0]
        new_outline, new_height = change.layout.outline, change.layout.height

        def switched(s):
            same = jnp.all(s.layout.outline == new_outline, axis=(-2, -1))
            return same & (change.at >= 0) & (s.time >= change.at)

        def step(carry, _):
            state, obs, alive, acc, post, top, steps = carry
            mask = env.action_masks(state, params) if env.shield else None
            a = actions.greedy_action(jnp, net.apply(q_params, obs), mask)
            obs2, state2, out = jax.vmap(env.advance, in_axes=(0, 0, None))(state, a, params)
            acc = outcome.accumulate(jnp, acc, out.info, alive)
            after = alive & switched(state)
            post = jnp.where(after, jnp.minimum(post, out.info.clearance), post)
            top = jnp.where(after, jnp.maximum(top, state2.heel[:, 1] - new_height), top)
            keep = lambda new, old: jnp.where(  # noqa: E731
                alive.reshape(alive.shape + (1,) * (new.ndim - 1)), new, old
            )
            state = jax.tree.map(keep, state2, state)
            obs = jnp.where(alive[:, None], obs2, obs)
            steps = steps + alive
            alive = alive & ~out.terminated & ~out.truncated
            return (state, obs, alive, acc, post, top, steps), None

        carry = (
            state,
            obs,
            jnp.ones(n, bool),
            outcome.start(jnp, (n,)),
            jnp.full(n, jnp.inf),
            jnp.full(n, -jnp.inf),
            jnp.zeros(n, jnp.int32),
        )
        (state, _, _, acc, post, top, steps), _ = jax.lax.scan(step, carry, None, length=max_steps)
        v = outcome.episode_verdict(jnp, acc, **outcome.rule(params))
        return Episodes(
            steps=steps,
            reached=acc.reached_goal,
            fired=switched(state),
            post_clearance=post,
            post_lift=top,
            limits=acc.limits,
            success=v.success,
        )

    return jax.jit(run)


def _changes(params, layouts, at, which: dict, rng):
    """The ObstacleChange of each layout for one kind of change (``which``: the change_* params it
    sets, the rest off), switching at step ``at`` (-1 where the change finds no room); drawn in
    NumPy from the environment's ``params`` (EnvParams) and ``layouts`` (Layout [N])."""
    import jax
    import jax.numpy as jnp

    off = dict(
        change_chance=np.float32(1.0),
        change_taller=np.zeros(2, np.float32),
        change_wider=np.zeros(2, np.float32),
        change_move=np.zeros(2, np.float32),
        change_second=np.float32(0.0),
        change_max_height=np.float32(geometry.MAX_OBSTACLE_HEIGHT),
        change_steps=np.asarray([1, 1], np.int32),
    )
    off.update({k: np.asarray(v, np.float32) for k, v in which.items()})
    p = jax.tree.map(np.asarray, params.replace(**off))
    n = len(at)
    u = rng.random((n, changes.N_UNIFORMS), dtype=np.float32)
    lay = jax.tree.map(np.asarray, layouts)
    c = changes.changed_layout(np, p, lay, u)
    new = layouts._replace(
        outline=jnp.asarray(c.outline, jnp.float32),
        shape=jnp.asarray(c.shape, jnp.float32),
        center_y=jnp.asarray(c.center_y, jnp.float32),
        width=jnp.asarray(c.width, jnp.float32),
        height=jnp.asarray(c.height, jnp.float32),
    )
    at = np.where(c.at >= 0, at, -1).astype(np.int32)
    from jaxexo.env.exo_step import ObstacleChange

    figures = {
        "height_ratio_median": float(np.median(c.height / lay.height)),
        "move_cm_median": float(100 * np.median(c.center_y - lay.center_y)),
        "width_ratio_median": float(np.median(c.width / lay.width)),
    }
    return ObstacleChange(at=jnp.asarray(at), layout=new), figures


def continuation(policies: dict, cfg, n: int = 1000, seed: int = 0) -> dict:
    """(b), with the shield (as the generator runs a policy; a shielded policy's raw greedy moves
    without it are not a swing): per change kind and policy, the episodes whose change fired (the
    foot clear of the new obstacle at the switch) and, of those, the success from the change (goal
    reached, the clearance after the switch >= env.min_clearance), the strict verdict of the whole
    episode, joint limits, the lift over the new obstacle; also on the scenes fired for every
    policy."""
    env_cfg = dataclasses.replace(cfg.env, obstacle_change=_spec_on())
    out = _continuation(policies, dataclasses.replace(cfg, env=env_cfg), n, seed)
    return {"n": n, "shield": bool(cfg.env.shield), **out}


def _continuation(policies: dict, on, n: int, seed: int) -> dict:
    from jaxexo.env import ExoStepEnv

    env = ExoStepEnv(on)
    params = env.default_params
    layouts = layout_set(on, n, SCENE_SEED)
    nets = {name: _network(pol) for name, pol in policies.items()}
    run = _greedy(env, next(iter(nets.values()))[0], on.env.max_steps)
    qs = {name: q for name, (_, q) in nets.items()}
    base = {name: _host(run(q, layouts, env.no_change(layouts), params)) for name, q in qs.items()}
    rng = np.random.default_rng(seed)
    frac = rng.uniform(*AT_FRACTION, n)
    # the same instants for every policy: the first (baseline) policy's swing on the unchanged scene
    at = np.maximum(1, np.round(frac * next(iter(base.values()))["steps"])).astype(np.int32)
    out = {
        "unchanged": {
            k: {"success": float(b["success"].mean()), "steps_median": float(np.median(b["steps"]))}
            for k, b in base.items()
        },
        "changes": {},
    }
    margin = float(on.env.min_clearance)
    for kind, which in CHANGES.items():
        change, geo = _changes(params, layouts, at, which, rng)
        res = {name: _host(run(q, layouts, change, params)) for name, q in qs.items()}
        all_fired = np.logical_and.reduce([r["fired"] for r in res.values()])
        row = {"geometry": geo, "fired_all": int(all_fired.sum())}
        for name, r in res.items():
            row[name] = _rates(r, all_fired, margin)
        out["changes"][kind] = row
        print(kind, row, flush=True)
    return out


def _rates(r: dict, all_fired, margin: float) -> dict:
    ok = r["reached"] & (r["post_clearance"] >= margin - 1e-9)
    f = r["fired"]
    share = lambda x, m: float(x[m].mean()) if m.any() else float("nan")  # noqa: E731
    return {
        "fired": int(f.sum()),
        "success_from_change": share(ok, f),
        "strict_success": share(r["success"], f),
        "success_on_all_fired": share(ok, all_fired),
        "limits": share(r["limits"], f),
        "lift_cm_median": 100 * float(np.median(r["post_lift"][f])) if f.any() else float("nan"),
        "steps_median": float(np.median(r["steps"][f])) if f.any() else float("nan"),
    }


def _spec_on():
    from jaxexo.config.changes import ChangeSpec

    return ChangeSpec(chance=1.0)


def _host(e: Episodes) -> dict:
    return {k: np.asarray(v) for k, v in e._asdict().items()}


def safety(policies: dict, paths: dict, cfg, n: int) -> dict:
    """(a): each policy's RL-alone figures (swing_quality_bench.run_set) on the three hidden sets."""
    out = {}
    for set_name, scenes in scene_sets(cfg, n).items():
        out[set_name] = {}
        for name in policies:
            gen = TrajectoryGenerator.load(paths[name])
            t0 = time.process_time()
            r = run_set({"rl": gen}, scenes, gen.config, None, 0.0)["rl"]
            out[set_name][name] = {
                "n": r.n,
                "safe": r.safe,
                "reached_goal": r.reached_goal,
                "lift_cm_median": r.lift_cm_median,
                "duration_s_median": r.duration_s_median,
                "duration_s_p95": r.duration_s_p95,
                "cpu_s": time.process_time() - t0,
            }
            print(set_name, name, out[set_name][name], flush=True)
    return out


def markdown(res: dict) -> str:
    names = list(res["policies"])
    lines = [
        "# Training with obstacle changes",
        "",
        "Policies: " + "; ".join(f"`{k}`: {v}" for k, v in res["policies"].items()) + ".",
        "",
        "## (a) The hidden safety sets, RL alone (fallback none)",
        "",
    ]
    rows = [
        (
            s,
            name,
            f"{r['n']} | {100 * r['safe']:.1f} | {100 * r['reached_goal']:.1f} | "
            f"{r['lift_cm_median']:.2f} | {r['duration_s_median']:.3f} | {r['duration_s_p95']:.3f}",
        )
        for s, per in res["safety"].items()
        for name, r in per.items()
    ]
    lines += table(
        ("set", "policy", "n", "safe %", "goal %", "lift median cm", "duration median s",
         "duration p95 s"),
        rows,
        "ll" + "r" * 6,
    )  # fmt: skip
    lines += _continuation_table(res["continuation"], names)
    return "\n".join(lines)


def _continuation_table(c: dict, names) -> list[str]:
    lines = [
        "",
        f"## (b) Mid-swing continuation, {'shielded' if c['shield'] else 'no shield (the config has none)'} "
        f"({c['n']} training-distribution layouts, seed "
        f"{SCENE_SEED}; the change at {AT_FRACTION[0]:.0%}-{AT_FRACTION[1]:.0%} of the swing)",
        "",
        "Unchanged scenes: "
        + "; ".join(
            f"`{k}` strict success {100 * v['success']:.1f} %, {v['steps_median']:.0f} steps"
            for k, v in c["unchanged"].items()
        ),
        "",
    ]
    rows = []
    for kind, row in c["changes"].items():
        for name in names:
            r = row[name]
            rows.append(
                (
                    kind,
                    name,
                    f"{r['fired']} | {100 * r['success_from_change']:.1f} | "
                    f"{100 * r['strict_success']:.1f} | {100 * r['limits']:.1f} | "
                    f"{r['lift_cm_median']:.2f} | {r['steps_median']:.0f} | {row['fired_all']} | "
                    f"{100 * r['success_on_all_fired']:.1f}",
                )
            )
    lines += table(
        ("change", "policy", "fired", "success from the change %", "strict %",
         "joint limit %", "lift over the new top cm (median)", "steps (median)",
         "fired for all", "success on those %"),
        rows,
        "ll" + "r" * 8,
    )  # fmt: skip
    return lines


def run_obstacle_change_benchmark(
    paths: dict, out_dir, n_safety: int = 600, n_change: int = 1000, tag: str = ""
) -> dict:
    """Both measurements for the policies ``paths`` ({name: policy.npz}), printed and (when
    ``out_dir``) written as obstacle_change[_tag]_<date>_<machine>.{json,md}."""
    from jaxexo.storage.policy_file import load_policy

    policies = {k: load_policy(p) for k, p in paths.items()}
    cfg = TrajectoryGenerator.load(next(iter(paths.values()))).config
    t0 = time.process_time()
    res = {
        "policies": {k: str(p) for k, p in paths.items()},
        "continuation": continuation(policies, cfg, n_change),
        "safety": safety(policies, paths, cfg, n_safety),
        "machine": machine_info(),
    }
    res["cpu_s"] = time.process_time() - t0
    text = markdown(res)
    print(text)
    if out_dir:
        write_result("obstacle_change" + (f"_{tag}" if tag else ""), res, text, out_dir)
    return res
