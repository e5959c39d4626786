"""Trainer benchmarks: throughput of whole updates, the default model's training run, the shield's mask
A/B and where an update's time goes; the steady rate through the driver is train_steady_bench.
Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax

from jaxexo.config import Config
from jaxexo.summary import Summary, table
from jaxexo.train.trainer import Hyperparams, Trainer

from benchlib.runner import Record, timed_calls


@dataclasses.dataclass(frozen=True)
class Throughput(Record):
    """Whole training updates' env-steps/s of one config (its settings, the median call's figures)."""

    trace: str
    control: str
    num_envs: int
    hidden: list
    rollout_steps: int
    env_steps_per_call: int
    median_s: float
    env_steps_per_s: float
    compile_s: float
    repeats: int
    devices: int


def throughput(cfg: Config, updates_per_call: int, repeats: int = 3, devices=None) -> Throughput:
    tr = Trainer(cfg, devices=devices)
    hyper = Hyperparams.from_config(cfg)
    # laid out as the chunks return it: one compilation (Trainer.place)
    ts = tr.place(jax.jit(tr.init)(jax.random.PRNGKey(0), hyper))
    run = jax.jit(tr.run, static_argnums=2)
    compile_s, times = timed_calls(lambda s: run(s, hyper, updates_per_call)[0], ts, repeats)
    steps = updates_per_call * cfg.train.num_envs * cfg.train.rollout_steps
    med = Summary.of(times).median
    t = cfg.train
    return Throughput(
        trace=t.trace,
        control=t.control,
        num_envs=t.num_envs,
        hidden=list(t.hidden),
        rollout_steps=t.rollout_steps,
        env_steps_per_call=steps,
        median_s=med,
        env_steps_per_s=steps / med,
        compile_s=compile_s,
        repeats=repeats,
        devices=len(tr.devices or [0]),
    )


def thesis_network_config(base: Config, trace: str, num_envs: int = 4096) -> Config:
    tc = dataclasses.replace(
        base.train,
        trace=trace,
        num_envs=num_envs,
        hidden=(64, 32, 32, 32),
        layer_norm=False,
        rollout_steps=16,
        num_minibatches=4,
        num_epochs=1,
        budget_env_steps=10**9,
        budget_episodes=0,
    )
    env = dataclasses.replace(base.env, obs_mode="thesis")
    return dataclasses.replace(base, train=tc, env=env)


def run_train_benchmark(
    out_dir, default_config: str = "configs/default.toml", thesis_configs=(), progress=print
) -> dict:
    """Throughput (thesis network, 4096 envs, forward view with 4 and 1 minibatches, backward view)
    and time-to-result of the default model and of the thesis configs, each through the real
    `jaxexo train` driver (compilation included in the wall time)."""
    import tempfile

    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result
    from jaxexo.train.driver import run_training

    base = load_config(default_config)
    rows = []
    devices = jax.local_devices()
    for trace, minibatches, updates in (("forward", 4, 10), ("forward", 1, 10), ("backward", 4, 1)):
        cfg = thesis_network_config(base, trace)
        cfg = dataclasses.replace(
            cfg, train=dataclasses.replace(cfg.train, num_minibatches=minibatches)
        )
        r = throughput(cfg, updates, repeats=3 if trace == "forward" else 2, devices=devices)
        r = {**r.to_dict(), "num_minibatches": minibatches}
        progress(
            f"thesis network, {trace} view, {minibatches} minibatch(es), 4096 envs, {r['devices']} device(s): "
            f"{r['env_steps_per_s'] / 1e6:.3f} M env-steps/s"
        )
        rows.append(r)
    runs = {}
    for name in [default_config, *thesis_configs]:
        with tempfile.TemporaryDirectory() as d:
            res = run_training(load_config(name), d, seed=0, progress=False)
        runs[name] = {
            k: res[k]
            for k in (
                "success_raw",
                "accuracy",
                "held_out",
                "by_obstacle",
                "train_seconds",
                "episodes",
                "env_steps",
            )
        }
        progress(
            f"{name}: trained in {res['train_seconds']:.1f} s, success_raw {res['success_raw']:.3f}, "
            f"held-out success_raw {(res['held_out'] or {}).get('success_raw')}"
        )
    tput = [
        (
            f"thesis network, {r['trace']} view"
            + ("" if r["trace"] == "backward" else f", {r['num_minibatches']} minibatch(es)/update")
            + f", {r['num_envs']} envs, {r['devices']} CPU devices",
            f"{r['env_steps_per_s'] / 1e6:.3f} M env-steps/s",
        )
        for r in rows
    ]
    head = "config|train wall s (incl. compile)|episodes|env steps|accuracy (eq 3.1)|"
    head += "strict success, raw moves|held-out, raw moves"
    cells = [
        (
            f"`{Path(name).relative_to(Path(name).parents[1]) if 'thesis' in name else Path(name).name}`",
            *(f"{r['train_seconds']:.1f}", r["episodes"], f"{r['env_steps']:,}"),
            *(f"{r[k]:.3f}" for k in ("accuracy", "success_raw")),
            f"{(r['held_out'] or {}).get('success_raw'):.3f}",
        )
        for name, r in runs.items()
    ]
    lines = ["# Trainer benchmarks", "", *table(("what", "figure"), tput), ""]
    lines += table(head.split("|"), cells)
    md = "\n".join(lines)
    write_result("train", {"throughput": rows, "runs": runs}, md, out_dir)
    progress(md)
    return {"throughput": rows, "runs": runs}


@dataclasses.dataclass(frozen=True)
class UpdateParts:
    """What update_breakdown times the parts of an update on: a trainer on one device, its
    hyperparameters, its first state, one rollout's transitions from it (``trans``), the acting
    epsilon and the optimizer."""

    tr: Trainer
    hyper: Hyperparams
    ts: object
    trans: object
    eps: object
    tx: object

    @classmethod
    def of(cls, cfg: Config) -> UpdateParts:
        import jax.numpy as jnp

        tr = Trainer(cfg)
        hyper = Hyperparams.from_config(cfg)
        ts = jax.jit(tr.init)(jax.random.PRNGKey(0), hyper)
        eps = jnp.float32(0.1)
        _, trans, _ = jax.jit(lambda s: tr._rollout(s, hyper, eps))(ts)
        return cls(tr, hyper, ts, trans, eps, tr.optimizer(hyper))

    @property
    def steps(self) -> int:
        """Minibatch steps per update."""
        c = self.tr.cfg.train
        return c.num_minibatches * c.num_epochs


def _timed_ms(fn, *args, repeats: int, calls: int) -> float:
    """Milliseconds per call of ``fn(i, *args)``: the median of ``repeats`` jitted loops of ``calls``
    iterations (after one that compiles)."""
    loop = jax.jit(lambda *a: jax.lax.fori_loop(0, calls, lambda i, acc: acc + fn(i, *a), 0.0))
    _, times = timed_calls(lambda _: loop(*args), None, repeats)
    return 1e3 * Summary.of(times).median / calls


def _total(tree):
    import jax.numpy as jnp

    return sum(jnp.sum(x).astype(jnp.float32) for x in jax.tree.leaves(tree))


def _env_steps(u: UpdateParts):
    """The rollout's T environment steps alone, on random moves (within the shield's mask where the
    config has it)."""
    import jax.numpy as jnp

    tr, hyper = u.tr, u.hyper
    t, n = tr.cfg.train.rollout_steps, tr.cfg.train.num_envs

    def env_steps(i, s):
        def one(c, k):
            es = c
            mask = tr._mask(es, hyper)
            a = (
                jax.random.randint(k, (n,), 0, tr.env.num_actions)
                if mask is None
                else jax.random.categorical(k, jnp.where(mask, 0.0, -jnp.inf), axis=-1).astype(
                    jnp.int32
                )
            )
            _, es, r, *_ = tr._env_step(k, es, a, hyper)
            return es, r.sum()

        _, r = jax.lax.scan(one, s.env_state, jax.random.split(jax.random.fold_in(s.key, i), t))
        return r.sum()

    return env_steps


def _acting(u: UpdateParts):
    """The rollout's T acting and target passes of the network."""
    net, t = u.tr.net, u.tr.cfg.train.rollout_steps

    def acting(i, s):  # each pass on its own input (identical passes would be computed once)
        return sum(
            net.apply(s.params, s.obs + 1e-6 * (i + j)).sum()
            + net.apply(s.target_params, s.obs - 1e-6 * (i + j)).sum()
            for j in range(t)
        )

    return acting


def _grads(u: UpdateParts):
    """The network's forward and backward passes over the update's minibatches."""
    import jax.numpy as jnp

    net, steps = u.tr.net, u.steps
    mb = u.tr.cfg.train.num_envs * u.tr.cfg.train.rollout_steps // u.tr.cfg.train.num_minibatches

    def grads(i, s, tr_):
        obs = tr_.obs.reshape((steps, -1) + tr_.obs.shape[2:])[:, :mb] + 1e-9 * i

        def loss(p, o):
            return 0.5 * jnp.mean(net.apply(p, o) ** 2)

        return sum(_total(jax.grad(loss)(s.params, obs[j % obs.shape[0]])) for j in range(steps))

    return grads


def _optimizer(u: UpdateParts):
    """The optimizer's steps of an update (clipping and Adam)."""
    import optax

    tx, steps = u.tx, u.steps

    def optimizer(i, s):
        g = jax.tree.map(lambda p: p * (1.0 + 1e-9 * i), s.params)
        p, o = s.params, s.opt_state
        for _ in range(steps):
            u_, o = tx.update(g, o, p)
            p = optax.apply_updates(p, u_)
        return _total(p)

    return optimizer


def _lambda_returns(u: UpdateParts):
    """The lambda-returns of one rollout's transitions."""
    from jaxexo.train import td_lambda

    hyper = u.hyper

    def returns(i, s, tr_):
        return td_lambda.lambda_returns(
            tr_.reward + 1e-9 * i,
            tr_.target_q,
            tr_.terminated,
            tr_.terminated | tr_.truncated,
            tr_.greedy,
            hyper.gamma,
            hyper.lam,
        ).sum()

    return returns


@dataclasses.dataclass(frozen=True)
class UpdateBreakdown(Record):
    """Where one update's time goes: the config's batch, and milliseconds per update by part."""

    num_envs: int
    rollout_steps: int
    num_minibatches: int
    num_epochs: int
    hidden: list
    shield: bool
    ms_per_update: dict
    env_steps_per_s_one_device: float


def update_breakdown(cfg: Config, repeats: int = 5, calls: int = 4) -> UpdateBreakdown:
    """Where one forward-view update's time goes, on one device at the config's batch: the whole
    update; its rollout (T steps of acting, environment, mask, target pass) and its learning part
    (lambda-returns, minibatch gradients, clipping and Adam) as the trainer runs them
    (``Trainer._rollout``, ``Trainer._learn``); and inside those, timed alone on the same shapes, the
    environment's steps (with the shield's mask where the config has it), the network's acting and
    target passes, its forward-and-backward passes over the minibatches, and the optimizer's steps.
    Medians of ``repeats`` jitted loops of ``calls`` iterations each, in milliseconds per update."""
    if cfg.train.trace != "forward":
        raise ValueError("update_breakdown: the forward view only (train.trace = 'forward')")
    u = UpdateParts.of(cfg)
    tr, hyper, ts, trans, eps = u.tr, u.hyper, u.ts, u.trans, u.eps
    t, n = cfg.train.rollout_steps, cfg.train.num_envs

    def timed(fn, *args):
        return _timed_ms(fn, *args, repeats=repeats, calls=calls)

    parts = {
        "update": timed(
            lambda i, s: _total(tr.update(s.replace(update=s.update * 0 + i), hyper)[1]), ts
        ),
        "rollout": timed(
            lambda i, s: _total(
                tr._rollout(s.replace(key=jax.random.fold_in(s.key, i)), hyper, eps)[1]
            ),
            ts,
        ),
        "learn": timed(
            lambda i, s, tr_: _total(
                tr._learn(s.replace(key=jax.random.fold_in(s.key, i)), tr_, hyper, eps)[1:]
            ),
            ts,
            trans,
        ),
        "environment steps" + (" with the mask" if tr.env.shield else ""): timed(_env_steps(u), ts),
        "network: acting and target passes": timed(_acting(u), ts),
        "network: forward and backward passes": timed(_grads(u), ts, trans),
        "optimizer: clipping and Adam": timed(_optimizer(u), ts),
        "lambda-returns": timed(_lambda_returns(u), ts, trans),
    }
    return UpdateBreakdown(
        num_envs=n,
        rollout_steps=t,
        num_minibatches=cfg.train.num_minibatches,
        num_epochs=cfg.train.num_epochs,
        hidden=list(cfg.train.hidden),
        shield=bool(tr.env.shield),
        ms_per_update=parts,
        env_steps_per_s_one_device=n * t / (parts["update"] / 1e3),
    )


def run_mask_ab_benchmark(path, updates: int, rounds: int, out_dir: Path) -> dict:
    """Steady env-steps/s of the shielded trainer with the plain mask (vmap(env.action_mask)) and with
    the batched one (env.action_masks, the trainer's), compiled once each and alternated A B A B so
    that a shared machine's load hits both alike; the medians of each."""
    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result

    cfg = load_config(path)
    hyper = Hyperparams.from_config(cfg)
    progs = {}
    for kind in ("plain", "batched"):
        tr = Trainer(cfg, devices=jax.local_devices())
        if kind == "plain":
            tr._mask = lambda st, h, tr=tr: jax.vmap(tr.env.action_mask, in_axes=(0, None))(
                st, h.env
            )
        ts = tr.place(jax.jit(tr.init)(jax.random.PRNGKey(0), hyper))
        run = jax.jit(tr.run, static_argnums=2)
        ts, _ = jax.block_until_ready(run(ts, hyper, updates))  # compiles
        progs[kind] = [run, ts, []]
    steps = updates * cfg.train.num_envs * cfg.train.rollout_steps
    for _ in range(rounds):
        for kind, prog in progs.items():
            run, ts, times = prog
            t0 = time.perf_counter()
            prog[1], _ = jax.block_until_ready(run(ts, hyper, updates))
            times.append(time.perf_counter() - t0)
    rates = {k: steps / Summary.of(v[2]).median for k, v in progs.items()}
    out = {
        "config": Path(path).name,
        "updates_per_call": updates,
        "rounds": rounds,
        "env_steps_per_call": steps,
        "devices": len(jax.local_devices()),
        "env_steps_per_s": rates,
        "times_s": {k: v[2] for k, v in progs.items()},
        "ratio": rates["batched"] / rates["plain"],
    }
    md = "\n".join(
        [
            f"# Shielded trainer, plain mask vs batched mask ({out['config']}, {out['devices']} CPU devices)",
            "",
            *table(
                ("mask", "steady env-steps/s (median)"),
                [(k, f"{v / 1e3:.0f}k") for k, v in rates.items()],
            ),
            "",
            f"Batched / plain: {out['ratio']:.2f}x; {rounds} alternated calls of {steps:,} env steps each. Shared "
            "machine: other jobs ran at the same time; the alternation exposes both to the same load.",
        ]
    )
    write_result("train-mask-ab", out, md, out_dir)
    print(md)
    return out


def run_breakdown_benchmark(paths, label: str, out_dir: Path) -> dict:
    """Where an update's time goes (update_breakdown), per config, written as
    train-breakdown[-label]_<date>_<machine>.{json,md}."""
    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result

    rows = []
    for path in paths:
        r = {**update_breakdown(load_config(path)).to_dict(), "config": Path(path).name}
        rows.append(r)
        print(r, flush=True)
    lines = [
        f"# Where a training update's time goes ({label or 'one device'})",
        "",
        "One forward-view update (T steps of N environments, then the learning part) on one CPU device "
        f"(of {len(jax.local_devices())}), each part timed alone on the update's own shapes in a jitted loop; "
        "milliseconds per update and share of the whole update. The parts inside the rollout and the "
        "learning part are measured alone, so they need not add up to their totals exactly.",
        "",
    ]
    for r in rows:
        parts = r["ms_per_update"]
        lines += [
            f"## {r['config']} (N = {r['num_envs']}, T = {r['rollout_steps']}, {r['num_minibatches']} "
            f"minibatches x {r['num_epochs']} epoch(s), hidden {r['hidden']}, shield {r['shield']})",
            "",
            *table(
                ("part", "ms per update", "share of the update"),
                [(k, f"{v:.2f}", f"{100 * v / parts['update']:.0f} %") for k, v in parts.items()],
            ),
        ]
        lines += ["", f"One device: {r['env_steps_per_s_one_device'] / 1e3:.0f}k env-steps/s.", ""]
    md = "\n".join(lines)
    write_result("train-breakdown" + (f"-{label}" if label else ""), {"rows": rows}, md, out_dir)
    print(md)
    return {"rows": rows}
