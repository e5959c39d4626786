"""The TD(lambda) trainer, its driver and the exported policy (jaxexo.train, jaxexo.storage.policy_file, CLI train).

JAX compile time dominates this file (a trainer update takes 5-6 s to compile on two CPU cores,
most of it the environment step), so:
- the runs are tiny and share one config (``tiny``) wherever they can;
- a persistent compilation cache in a temporary folder (this module only) lets the driver's runs
  reuse the programs that the determinism tests compiled;
- the uninterrupted reference run of the resume test is ``jaxexo train`` in a niced subprocess,
  started with the module, so that it runs on the core this process leaves idle (it is also the
  CLI test);
- the smoke runs of the other trace views and controls compile at XLA's lowest optimisation level.
The one long test is the learning test, which must show real learning.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict, load_config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.policy_file import FORMAT_VERSION, PolicyFileError, load_policy, policy_checksum

from conftest import ROOT, jax_compilation_cache

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.train import driver  # noqa: E402
from jaxexo.train.evaluate import HELD_OUT, TEST_KINDS, make_rollout  # noqa: E402
from jaxexo.train.trainer import METRICS, Hyperparams, Trainer, make_train  # noqa: E402

COL = {m: i for i, m in enumerate(METRICS)}


@pytest.fixture(scope="module", autouse=True)
def _compilation_cache(tmp_path_factory):
    """A persistent compilation cache for this module only: identical programs (the driver's init,
    chunk and evaluation programs, run again by the resume and CLI tests) are compiled once."""
    with jax_compilation_cache(tmp_path_factory.mktemp("jax_cache")) as cache:
        yield cache


# A fixed scene: Base 1 at the default place, pivot under the obstacle, no start shift or jitter.
FIXED_LAYOUT = {"obstacles": ["base1"], "pivot": ["obstacle"]}
# configs/default.toml's [reward]
REWARD = {"traj_weights": [0.0, 2.0, 0.5, 4.0, 0.5, 0.5, 1.0, 0.5], "exo_weights": [1.0, 1.0, 2.0, 1.0],
          "goal_reward": 20.0, "joint_limit_penalty": 4.0, "progress_shaping": 5.0}
# The shared tiny config: Watkins Q(lambda) in the backward view (its checkpoint then holds traces,
# the pending action and its greediness too), 6 updates in 3 chunks of 2.
TINY_N, TINY_T, TINY_UPDATES = 64, 8, 6
TINY_TRAIN = {
    "num_envs": TINY_N, "rollout_steps": TINY_T, "num_minibatches": 2, "hidden": [32, 32], "layer_norm": True,
    "trace": "backward", "control": "off_policy", "trace_kind": "accumulating",
    "lr": 1e-3, "gamma": 0.98, "lam": 0.9, "budget_env_steps": TINY_N * TINY_T * TINY_UPDATES,
    "chunk_updates": 2, "eval_episodes": 20,
}


def tiny_raw(**train) -> dict:
    return {"env": {"obs_mode": "conditioned"}, "layout": dict(FIXED_LAYOUT), "reward": dict(REWARD),
            "train": {**TINY_TRAIN, **train}}


def tiny_config(**train):
    return config_from_dict(tiny_raw(**train))


def leaves(tree) -> list[np.ndarray]:
    return [np.asarray(x) for x in jax.tree.leaves(tree)]


def trees_equal(a, b) -> bool:
    la, lb = leaves(a), leaves(b)
    return len(la) == len(lb) and all(x.dtype == y.dtype and np.array_equal(x, y) for x, y in zip(la, lb))


def all_finite(tree) -> bool:
    return all(np.all(np.isfinite(x)) for x in leaves(tree) if np.issubdtype(x.dtype, np.floating))


def avals(tree) -> list[tuple]:
    return [(x.shape, x.dtype, x.weak_type) for x in jax.tree.leaves(tree)]


# --------------------------------------------------------------------------------------------
# Learning
# --------------------------------------------------------------------------------------------

LEARN_SEED = 0
LEARN_TRAIN = {
    "num_envs": 128, "rollout_steps": 8, "num_minibatches": 4, "hidden": [64, 64], "layer_norm": True,
    "trace": "forward", "control": "off_policy", "lr": 3e-4, "lr_end_fraction": 0.1, "gamma": 0.98,
    "lam": 0.9, "eps_start": 1.0, "eps_end": 0.02, "eps_decay_fraction": 0.5, "budget_env_steps": 600_000,
}


@pytest.mark.slow
def test_trainer_learns_to_step_over_a_fixed_obstacle():
    """Watkins Q(lambda), forward view, on one fixed layout: from ~0 training successes (random
    behaviour) to a success rate above 0.8 in the last tenth of a 600 k env-step budget, and the
    greedy policy clears the obstacle. Observed over seeds 0-9: first tenth 0.000 on every seed, last
    tenth 0.979-1.000, greedy success in 28-34 steps on every seed."""
    from jaxexo.physics.geometry import Obstacle

    cfg = config_from_dict({"env": {"obs_mode": "conditioned"}, "layout": dict(FIXED_LAYOUT),
                            "reward": dict(REWARD), "train": LEARN_TRAIN})
    trainer = Trainer(cfg)
    hyper = Hyperparams.from_config(cfg)
    assert trainer.num_updates == 586
    ts = jax.jit(trainer.init)(jax.random.PRNGKey(LEARN_SEED), hyper)
    ts, m = jax.jit(trainer.run, static_argnums=2)(ts, hyper, trainer.num_updates)
    m = np.asarray(m)
    assert int(trainer.env_steps(ts)) == trainer.num_updates * 128 * 8
    tenth = len(m) // 10

    def rate(rows):
        assert rows[:, COL["episodes"]].sum() >= 200
        return rows[:, COL["successes"]].sum() / rows[:, COL["episodes"]].sum()

    first, last = rate(m[:tenth]), rate(m[-tenth:])
    assert first < 0.05, (first, last)
    assert last > 0.8, (first, last)
    assert m[-1, COL["epsilon"]] == pytest.approx(0.02)

    # Greedy evaluation on the same fixed scene, built by hand: it is the scene training saw.
    env = trainer.env
    layout = env.layout_for(Obstacle.named("base1"), pivot="obstacle", start_y=0.0, step_length=0.70)
    obs_fixed, _ = env.init_state(layout, env.default_params)
    obs_reset, _ = env.reset(jax.random.PRNGKey(1), env.default_params)
    np.testing.assert_allclose(obs_fixed, obs_reset, atol=1e-6)
    out = jax.jit(make_rollout(env, trainer.net.apply, cfg.env.max_steps))(ts.params, layout, env.default_params)
    assert bool(out["reached"]) and bool(out["success"]), {k: np.asarray(v).tolist() for k, v in out.items()}
    assert int(out["steps"]) < cfg.env.max_steps


# --------------------------------------------------------------------------------------------
# Determinism, views and controls, make_train
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny():
    """The shared tiny config's trainer with its jitted init and run (the driver's programs too)."""
    cfg = tiny_config()
    trainer = Trainer(cfg)
    return {"cfg": cfg, "trainer": trainer, "hyper": Hyperparams.from_config(cfg), "init": jax.jit(trainer.init),
            "run": jax.jit(trainer.run, static_argnums=2)}


def test_same_seed_is_bitwise_deterministic_and_seeds_differ(tiny):
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    a, ma = run(init(jax.random.PRNGKey(5), hyper), hyper, 2)
    b, mb = run(init(jax.random.PRNGKey(5), hyper), hyper, 2)
    c, mc = run(init(jax.random.PRNGKey(6), hyper), hyper, 2)
    assert trees_equal(a.params, b.params) and trees_equal(a.opt_state, b.opt_state)
    assert trees_equal(a, b)
    np.testing.assert_array_equal(np.asarray(ma), np.asarray(mb))
    assert not np.array_equal(leaves(a.params)[0], leaves(c.params)[0])
    assert not np.array_equal(np.asarray(ma), np.asarray(mc))
    # The updates really changed the parameters from their initial values.
    a0 = init(jax.random.PRNGKey(5), hyper)
    assert all(not np.array_equal(x, y) for x, y in zip(leaves(a.params), leaves(a0.params)))


def test_budget_freezes_the_state(tiny):
    # Updates past the budget (6 updates here) leave the state alone and report zero metrics
    # (vmapped seeds and sweeps finish at different times).
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    ts = init(jax.random.PRNGKey(1), hyper)
    for _ in range(TINY_UPDATES // 2):
        assert bool(jax.jit(tiny["trainer"].active)(ts, hyper))
        ts, m = run(ts, hyper, 2)
        assert np.all(np.asarray(m)[:, COL["env_steps"]] == TINY_N * TINY_T)
    assert int(ts.update) == TINY_UPDATES and not bool(jax.jit(tiny["trainer"].active)(ts, hyper))
    ts2, m2 = run(ts, hyper, 2)
    assert trees_equal(ts, ts2)
    assert np.all(np.asarray(m2) == 0)


def test_epsilon_schedule(tiny):
    # Linear from eps_start to eps_end over eps_decay_fraction (0.5) of the 6-update budget.
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    ts, m = run(init(jax.random.PRNGKey(1), hyper), hyper, 2)
    _, m2 = run(ts, hyper, 2)
    eps = np.concatenate([np.asarray(m)[:, COL["epsilon"]], np.asarray(m2)[:, COL["epsilon"]]])
    expect = [0.02 + 0.98 * max(0.0, 1 - (k / TINY_UPDATES) / 0.5) for k in range(4)]
    np.testing.assert_allclose(eps, expect, rtol=1e-5)


def test_state_types_are_stable_across_updates(tiny):
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    ts0 = init(jax.random.PRNGKey(5), hyper)
    ts1, _ = run(ts0, hyper, 2)
    assert avals(ts1) == avals(ts0)


COMBOS = [
    ("backward", "off_policy", "accumulating"),   # the tiny config
    ("backward", "off_policy", "replacing"),
    ("backward", "on_policy", "accumulating"),
    ("backward", "on_policy", "replacing"),       # through make_train, vmapped over 2 seeds
    ("forward", "on_policy", "accumulating"),
]
COMBO_UPDATES = 2


# These smoke runs are compiled at XLA's lowest backend optimisation level: half the compile time,
# the same program (the driver, determinism and learning tests use the default level).
FAST = {"xla_backend_optimization_level": 0}


def fast_compile(fun, *args, static_argnums=()):
    return jax.jit(fun, static_argnums=static_argnums).lower(*args).compile(compiler_options=FAST)


@pytest.fixture(scope="module")
def compiled_runs(tiny):
    """A few updates of every trace view x control x trace kind, one of them through make_train
    jitted and vmapped over two seeds."""
    def combo_config(combo, **kw):
        trace, control, kind = combo
        return tiny_config(trace=trace, control=control, trace_kind=kind, **kw)

    # The initial state depends on the view only, not on the control or trace kind.
    start = jax.random.split(jax.random.PRNGKey(0), 2)   # make_train: both keys; the others: the first
    hyper = tiny["hyper"]
    fwd_init = Trainer(combo_config(COMBOS[-1])).init
    starts = {"backward": tiny["init"](start[0], hyper),
              "forward": fast_compile(fwd_init, start[0], hyper)(start[0], hyper)}

    def one(combo):
        ts0 = starts[combo[0]]
        if combo == COMBOS[0]:
            run = lambda ts, hyper: tiny["run"](ts, hyper, COMBO_UPDATES)  # noqa: E731
        else:
            run = fast_compile(Trainer(combo_config(combo)).run, ts0, hyper, COMBO_UPDATES, static_argnums=2)
        ts, m = run(ts0, hyper)
        return combo, {"hyper": hyper, "run": run, "ts0": ts0, "ts": ts, "m": np.asarray(m)}

    def vmapped_make_train(combo):
        # The whole 6-update budget in one program, per seed.
        ts, m = fast_compile(jax.vmap(make_train(combo_config(combo)), in_axes=(0, None)), start, hyper)(start, hyper)
        first = jax.tree.map(lambda x: x[0], ts)
        return combo, {"ts0": starts["backward"], "ts": first, "m": np.asarray(m)[0], "vmapped": (ts, np.asarray(m))}

    runs = dict(one(c) for c in COMBOS if c != COMBOS[3])
    runs.update([vmapped_make_train(COMBOS[3])])
    return runs


@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(c) for c in COMBOS])
def test_views_and_controls_run(compiled_runs, combo):
    r = compiled_runs[combo]
    ts0, ts, m = r["ts0"], r["ts"], r["m"]
    n_upd = TINY_UPDATES if "vmapped" in r else COMBO_UPDATES
    trace = combo[0]
    assert m.shape == (n_upd, len(METRICS))
    assert np.all(np.isfinite(m))
    assert int(ts.update) == n_upd
    np.testing.assert_array_equal(m[:, COL["env_steps"]], TINY_N * TINY_T)
    assert np.all(m[:, COL["loss"]] > 0)
    assert all_finite(ts.params) and all_finite(ts.target_params)
    assert all(not np.array_equal(x, y) for x, y in zip(leaves(ts.params), leaves(ts0.params)))
    if trace == "backward":
        # Per-environment traces over every parameter, finite and in use.
        for e, p in zip(leaves(ts.traces), leaves(ts.params)):
            assert e.shape == (TINY_N,) + p.shape
        assert all_finite(ts.traces)
        assert any(np.abs(e).max() > 0 for e in leaves(ts.traces))
    else:
        assert ts.traces == ()


def test_controls_and_trace_kinds_are_different_algorithms(compiled_runs):
    # From the same initial state and keys: accumulating vs replacing, Watkins vs SARSA differ.
    final = {c: leaves(compiled_runs[c]["ts"].params)[0] for c in COMBOS[:3]}
    assert not np.array_equal(final[COMBOS[0]], final[COMBOS[1]])
    assert not np.array_equal(final[COMBOS[0]], final[COMBOS[2]])


@pytest.mark.parametrize("control", ["on_policy", "off_policy"])
def test_backward_traces_reset_at_episode_start_and_watkins_cut(compiled_runs, control):
    """Stale traces never leak into a fresh episode (bitwise: the reset multiplies them by 0), and
    under Watkins Q(lambda) an exploratory action cuts them the same way; without either, they do
    leak (so the check can fail)."""
    r = compiled_runs[("backward", control, "accumulating")]
    ts0, run, hyper = r["ts0"], r["run"], r["hyper"]
    assert bool(np.all(np.asarray(ts0.fresh)))
    rng = np.random.default_rng(42)
    stale = jax.tree.map(lambda e: rng.normal(size=e.shape).astype(e.dtype), ts0.traces)
    n = ts0.fresh.shape[0]
    go = lambda ts: run(ts, hyper)[0]  # noqa: E731
    ref = r["ts"]
    assert trees_equal(go(ts0.replace(traces=stale)), ref)
    leak = go(ts0.replace(traces=stale, fresh=jnp.zeros(n, bool), greedy=jnp.ones(n, bool)))
    assert not np.array_equal(leaves(leak.params)[0], leaves(ref.params)[0])
    cut = go(ts0.replace(traces=stale, fresh=jnp.zeros(n, bool), greedy=jnp.zeros(n, bool)))
    if control == "off_policy":
        assert trees_equal(cut.params, ref.params)
    else:
        assert not np.array_equal(leaves(cut.params)[0], leaves(ref.params)[0])


def test_make_train_jit_vmaps_over_seeds(compiled_runs):
    ts, m = compiled_runs[COMBOS[3]]["vmapped"]
    assert m.shape == (2, TINY_UPDATES, len(METRICS))
    assert np.all(np.isfinite(m)) and all_finite(ts.params)
    np.testing.assert_array_equal(np.asarray(ts.update), [TINY_UPDATES] * 2)
    np.testing.assert_array_equal(Trainer(tiny_config()).env_steps(ts), [TINY_UPDATES * TINY_N * TINY_T] * 2)
    for leaf in leaves(ts.params):
        assert leaf.shape[0] == 2 and not np.array_equal(leaf[0], leaf[1])
    assert not np.array_equal(m[0], m[1])


def test_epsilon_greedy_value_matches_the_behaviour_policy(tiny):
    """The SARSA bootstrap where the next action is unknown (td_lambda.epsilon_greedy_value) is the
    expectation of Q under the trainer's own epsilon-greedy action choice."""
    from jaxexo.train import td_lambda

    trainer = tiny["trainer"]
    ts = tiny["init"](jax.random.PRNGKey(3), tiny["hyper"])
    n, m = 4, 20000
    obs, params = ts.obs[:n], ts.params

    @jax.jit
    def mc(key, eps):
        big = jnp.repeat(obs, m, axis=0)
        a, greedy = trainer._act(params, big, key, eps)
        q = trainer.net.apply(params, big)
        qa = jnp.take_along_axis(q, a[:, None], axis=-1)[:, 0].reshape(n, m)
        return qa.mean(1), qa.std(1), greedy.reshape(n, m).mean(1), td_lambda.epsilon_greedy_value(q[::m], eps)

    for eps in (0.0, 0.3, 1.0):
        mean, std, greedy_share, expect = (np.asarray(x) for x in mc(jax.random.PRNGKey(2), eps))
        np.testing.assert_allclose(mean, expect, atol=4 * std.max() / np.sqrt(m) + 1e-6)
        # an exploratory draw can still pick the greedy action: 1 - eps + eps / 36 of them are greedy
        np.testing.assert_allclose(greedy_share, 1 - eps + eps / trainer.env.num_actions, atol=0.015)
    assert std.max() > 0.01   # Q differs across actions: the comparison above has teeth


# --------------------------------------------------------------------------------------------
# Background runs of ``jaxexo train`` (subprocesses)
# --------------------------------------------------------------------------------------------

SEED = 3
CLI_TEST = "test_cli_train_writes_the_run_directory"


def _cli_cmd(*args):
    return [sys.executable, "-m", "jaxexo.cli", *map(str, args)]


class _Background:
    """``jaxexo train CONFIG --out OUT --quiet`` in a niced subprocess: it takes the core this process
    leaves idle while the tests here run."""

    def __init__(self, cfg, tmp, seed: int, devices: int | None):
        self.cfg, self.cfg_path, self.out = cfg, tmp / "config_in.toml", tmp / "run"
        self.cfg_path.write_text(config_to_toml(cfg))
        env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
        if devices is not None:   # else the CLI exposes every CPU core (jaxexo.train.devices)
            env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
        self.proc = subprocess.Popen(_cli_cmd("train", self.cfg_path, "--out", self.out, "--quiet", "--seed", seed),
                                     cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            os.setpriority(os.PRIO_PROCESS, self.proc.pid, 15)
        except (AttributeError, OSError):   # no setpriority on this platform: run at normal priority
            pass
        self.result = None

    def wait(self):
        if self.result is None:
            self.result = self.proc.communicate(timeout=600)
        assert self.proc.returncode == 0, self.result[1][-3000:]
        return self.result

    def stop(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


@pytest.fixture(scope="module", autouse=True)
def background(request, tmp_path_factory):
    """Started with this module if a test selected needs it: the uninterrupted run of the tiny
    config on one device, by the CLI, that the driver tests compare a resumed run with (bit for bit)
    and that the CLI test checks."""
    items = [i for i in request.session.items if i.module is request.module]
    runs = {}
    if any("driver_runs" in i.fixturenames or i.name == CLI_TEST for i in items):
        runs["reference"] = _Background(tiny_config(), tmp_path_factory.mktemp("reference"), SEED, devices=1)
    yield runs
    for r in runs.values():
        r.stop()


# --------------------------------------------------------------------------------------------
# The driver: resume, eval.json, policy export
# --------------------------------------------------------------------------------------------

class _Interrupt:
    """Patches driver._atomic_write to raise KeyboardInterrupt on its ``at``-th call (calls go
    checkpoint, bookkeeping, checkpoint, bookkeeping, ... one pair per finished chunk)."""

    def __init__(self, at: int):
        self.at, self.calls = at, 0
        self.real = driver._atomic_write

    def __call__(self, path, data):
        self.calls += 1
        if self.calls == self.at:
            raise KeyboardInterrupt
        return self.real(path, data)


def _interrupted_then_resumed(cfg, out, at: int) -> dict:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(driver, "_atomic_write", _Interrupt(at))
        with pytest.raises(KeyboardInterrupt):
            driver.run_training(cfg, out, seed=SEED, progress=False, eval_episodes=20)
    before = {
        "book": json.loads((out / driver.BOOKKEEPING).read_text()),
        "metric_lines": len((out / "metrics.jsonl").read_text().splitlines()),
        "policy": (out / "policy.npz").exists(),
    }
    res = driver.run_training(cfg, out, seed=SEED, resume=True, progress=False, eval_episodes=20)
    return {"before": before, "result": res}


@pytest.fixture(scope="module")
def driver_runs(background, tmp_path_factory):
    """A 6-update run in 3 chunks of 2, run straight through (by the CLI, in the background), and
    the same run here, killed while saving the checkpoint of chunk 2 (its metrics line already
    written) and resumed."""
    cfg = tiny_config()
    part = tmp_path_factory.mktemp("runs") / "part"
    resumed = _interrupted_then_resumed(cfg, part, at=3)
    ref = background["reference"]
    ref.wait()
    assert load_config(ref.out / "config.toml") == cfg
    res_full = json.loads((ref.out / "eval.json").read_text())
    return {"cfg": cfg, "full": ref.out, "part": part, "res_full": res_full, **resumed}


def _counters(path) -> list[dict]:
    rows = [json.loads(x) for x in path.read_text().splitlines()]
    return [{k: v for k, v in r.items() if k not in ("wall_s", "env_steps_per_s")} for r in rows]


def _npz(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


@pytest.mark.parametrize("which", ["full", "part"])
def test_run_directory_is_complete(driver_runs, which):
    out = driver_runs[which]
    for name in ("config.toml", "metrics.jsonl", "policy.npz", "training_curve.png", "eval.json",
                 driver.CHECKPOINT, driver.BOOKKEEPING):
        assert (out / name).is_file(), name
    assert load_config(out / "config.toml") == driver_runs["cfg"]
    rows = _counters(out / "metrics.jsonl")
    assert [r["chunk"] for r in rows] == [1, 2, 3]
    assert [r["updates"] for r in rows] == [2, 4, 6]
    assert [r["env_steps"] for r in rows] == [k * 2 * TINY_N * TINY_T for k in (1, 2, 3)]
    assert all(0.0 <= r["validation_success"] <= 1.0 for r in rows)
    book = json.loads((out / driver.BOOKKEEPING).read_text())
    assert book["chunks_done"] == 3 and book["seed"] == SEED
    assert (out / "training_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_resume_is_bit_identical(driver_runs):
    full, part = driver_runs["full"], driver_runs["part"]
    before = driver_runs["before"]
    # The interruption happened where intended: chunk 1 saved, chunk 2's metrics line written but
    # its checkpoint not, no policy yet.
    assert before["book"]["chunks_done"] == 1 and before["metric_lines"] == 2 and not before["policy"]
    assert (full / driver.CHECKPOINT).read_bytes() == (part / driver.CHECKPOINT).read_bytes()
    pf, pp = _npz(full / "policy.npz"), _npz(part / "policy.npz")
    assert sorted(pf) == sorted(pp) and len(pf) >= 7
    for k in pf:
        assert pf[k].dtype == pp[k].dtype and np.array_equal(pf[k], pp[k]), k
    assert _counters(full / "metrics.jsonl") == _counters(part / "metrics.jsonl")
    drop = lambda r: {k: v for k, v in r.items() if k != "train_seconds"}  # noqa: E731
    assert drop(driver_runs["res_full"]) == drop(driver_runs["result"])
    assert drop(json.loads((part / "eval.json").read_text())) == drop(driver_runs["result"])


def test_resume_after_an_interrupt_between_checkpoint_and_bookkeeping(driver_runs, tmp_path):
    """Stopped after writing chunk 2's checkpoint but before its readable bookkeeping copy (stale:
    chunk 1's): the run resumes from that checkpoint and ends as the uninterrupted one (when the
    bookkeeping was a separate file that resume read, it lost a metrics row)."""
    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(driver, "_atomic_write", _Interrupt(4))
        with pytest.raises(KeyboardInterrupt):
            driver.run_training(driver_runs["cfg"], out, seed=SEED, progress=False, eval_episodes=20)
    driver.run_training(driver_runs["cfg"], out, seed=SEED, resume=True, progress=False, eval_episodes=20)
    assert _counters(driver_runs["full"] / "metrics.jsonl") == _counters(out / "metrics.jsonl")
    assert (driver_runs["full"] / driver.CHECKPOINT).read_bytes() == (out / driver.CHECKPOINT).read_bytes()


def test_eval_json(driver_runs):
    res = json.loads((driver_runs["full"] / "eval.json").read_text())
    for key in ("accuracy", "success", "by_obstacle", "by_pivot", "episodes", "env_steps", "train_seconds",
                "held_out"):
        assert key in res, key
    assert set(res["by_obstacle"]) == set(TEST_KINDS) and len(TEST_KINDS) == 5
    assert set(res["by_pivot"]) == {"agent", "obstacle", "between"}
    assert sum(v["n"] for v in res["by_obstacle"].values()) == 20
    assert sum(v["n"] for v in res["by_pivot"].values()) == 20
    assert res["held_out"]["n"] == sum(res["by_obstacle"][k]["n"] for k in HELD_OUT)
    for fig in [res, res["held_out"], *res["by_obstacle"].values(), *res["by_pivot"].values()]:
        assert 0.0 <= fig["success"] <= fig["accuracy"] <= 1.0
    assert res["env_steps"] == TINY_UPDATES * TINY_N * TINY_T
    ck = json.loads((driver_runs["full"] / "metrics.jsonl").read_text().splitlines()[-1])
    assert res["episodes"] == ck["episodes"]
    assert res["train_seconds"] > 0 and res["seed"] == SEED


def test_exported_policy_matches_the_checkpoint(driver_runs, tiny):
    """policy.npz holds the checkpoint's selected (best validation) parameters, computing the same Q."""
    from flax import serialization

    from jaxexo.storage.checkpoint import unpack_checkpoint

    cfg, full = driver_runs["cfg"], driver_runs["full"]
    trainer, hyper = tiny["trainer"], tiny["hyper"]
    template = tiny["init"](jax.random.PRNGKey(0), hyper)
    saved = serialization.from_bytes({"state": template, "best_params": template.params},
                                     unpack_checkpoint((full / driver.CHECKPOINT).read_bytes(), "ckpt"))
    assert int(saved["state"].update) == TINY_UPDATES
    pol = load_policy(full / "policy.npz")
    assert pol.metadata["layer_norm"] is True and pol.metadata["layers"] == [trainer.env.obs_dim, 32, 32, 36]
    assert config_from_dict(tomllib.loads(pol.metadata["config_toml"])) == cfg   # and the whole config
    obs = template.obs   # 64 observations of fresh episodes
    q = np.asarray(jax.jit(trainer.net.apply)(saved["best_params"], obs))
    np.testing.assert_allclose(pol.q_values(np.asarray(obs)), q, rtol=1e-5, atol=1e-5)


def random_params(net, obs_dim: int, seed: int):
    """The network's parameter tree (flax's names and shapes) with random values everywhere,
    LayerNorm scales and biases included (not the initial ones: zero biases, unit scales)."""
    rng = np.random.default_rng(seed)
    shapes = jax.eval_shape(net.init, jax.random.PRNGKey(0), jnp.zeros((1, obs_dim)))
    return jax.tree.map(lambda s: (rng.normal(size=s.shape) * 0.5 + (1.0 if s.ndim == 1 else 0.0)).astype(s.dtype),
                        shapes)


@pytest.mark.parametrize("layer_norm", [False, True])
def test_policy_round_trip(tmp_path, layer_norm):
    cfg = tiny_config(layer_norm=layer_norm, hidden=[24, 16, 8])
    trainer = Trainer(cfg)
    d = trainer.env.obs_dim
    params = random_params(trainer.net, d, seed=1)
    path = driver.export_policy(tmp_path / "policy.npz", cfg, trainer, params)
    with zipfile.ZipFile(path) as z:   # plain arrays, no pickled objects
        assert all(n.endswith(".npy") for n in z.namelist())
    pol = load_policy(path)
    assert pol.obs_dim == d and pol.num_actions == 36
    assert pol.metadata["format_version"] == FORMAT_VERSION and pol.metadata["layer_norm"] is layer_norm
    assert len(pol.norm_scales) == (3 if layer_norm else 0)
    obs = np.random.default_rng(0).normal(size=(256, d)).astype(np.float32) * 2
    ref = np.asarray(jax.jit(trainer.net.apply)(params, jnp.asarray(obs)))
    q = pol.q_values(obs)
    assert q.shape == (256, 36)
    np.testing.assert_allclose(q, ref, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(pol.q_values(obs[0]), ref[0], rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(pol.greedy_action(obs), ref.argmax(-1))
    with pytest.raises(ValueError, match="last dimension"):
        pol.q_values(obs[:, :-1])


def test_narrow_input_layer_is_a_matrix_product():
    """The thesis observation (heel y, z) enters the first layer as scaled kernel rows
    (network.NARROW_INPUT): the Q-values and their gradients are those of the plain matrix product."""
    from jaxexo.train.network import QNetwork, dense_layers

    net = QNetwork(hidden=(64, 32), num_actions=36)
    x = jax.random.normal(jax.random.PRNGKey(1), (512, 2))
    params = net.init(jax.random.PRNGKey(0), x[:1])

    def plain(params, x):
        layers = dense_layers(params)
        for w, b in layers[:-1]:
            x = jnp.maximum(x @ w + b, 0.0)
        return x @ layers[-1][0] + layers[-1][1]

    np.testing.assert_allclose(net.apply(params, x), plain(params, x), rtol=1e-5, atol=1e-6)
    loss = lambda f: lambda p: jnp.mean(f(p, x)[:, 3] ** 2)  # noqa: E731
    g_net, g_plain = jax.grad(loss(net.apply))(params), jax.grad(loss(plain))(params)
    for a, b in zip(leaves(g_net), leaves(g_plain)):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)
    assert np.abs(leaves(g_net)[1]).max() > 0   # dense_0's kernel gradient is not trivially zero


# --------------------------------------------------------------------------------------------
# Broken policy files
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def good_policy(tmp_path_factory):
    cfg = tiny_config(hidden=[8], layer_norm=True)
    trainer = Trainer(cfg)
    params = random_params(trainer.net, trainer.env.obs_dim, seed=0)
    path = driver.export_policy(tmp_path_factory.mktemp("pol") / "policy.npz", cfg, trainer, params)
    load_policy(path)
    return path


def _rewrite(src, dst, meta=None, fix_checksum=True, **arrays):
    """A copy of the policy file with metadata fields replaced (None: removed) and arrays replaced (None:
    removed); its checksum recomputed unless ``fix_checksum`` is False, so that the check under test is
    the one that refuses the file (tampering without a new checksum is test_reliability's)."""
    files = _npz(src)
    if meta is not None:
        m = json.loads(str(files["metadata"]))
        m.update(meta)
        m = {k: v for k, v in m.items() if v is not None}
        files["metadata"] = np.array(json.dumps(m))
    for k, v in arrays.items():
        if v is None:
            files.pop(k)
        else:
            files[k] = v
    if fix_checksum and "metadata" not in arrays:
        try:
            m = json.loads(str(files["metadata"]))
        except (KeyError, ValueError):
            m = None
        if isinstance(m, dict):
            m["sha256"] = policy_checksum({k: v for k, v in files.items() if k != "metadata"}, m)
            files["metadata"] = np.array(json.dumps(m))
    np.savez(dst, **files)
    return dst


def test_policy_file_errors(good_policy, tmp_path):
    data = good_policy.read_bytes()
    cases = {}
    cases["missing"] = (tmp_path / "nope.npz", "no such policy file")
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    cases["truncated"] = (tmp_path / "trunc.npz", "truncated or corrupt")
    (tmp_path / "empty.npz").write_bytes(b"")
    cases["empty"] = (tmp_path / "empty.npz", "truncated or corrupt")
    (tmp_path / "junk.npz").write_bytes(b"this is not a zip file at all" * 10)
    cases["junk"] = (tmp_path / "junk.npz", "not a readable policy file")
    cases["version"] = (_rewrite(good_policy, tmp_path / "v.npz", {"format_version": FORMAT_VERSION + 1}),
                        f"format_version {FORMAT_VERSION + 1}")
    cases["format"] = (_rewrite(good_policy, tmp_path / "f.npz", {"format": "other"}), "format is 'other'")
    k0 = _npz(good_policy)["dense_0_kernel"]
    cases["shape"] = (_rewrite(good_policy, tmp_path / "s.npz", dense_0_kernel=k0.T), "dense_0 has shapes")
    cases["layers"] = (_rewrite(good_policy, tmp_path / "l.npz", {"layers": [5, 8, 36], "obs_dim": 5}), "dense_0 has shapes")
    cases["missing_array"] = (_rewrite(good_policy, tmp_path / "m.npz", dense_1_bias=None), "missing array 'dense_1_bias'")
    cases["nan"] = (_rewrite(good_policy, tmp_path / "n.npz", dense_1_bias=np.full(36, np.nan, np.float32)),
                    "'dense_1_bias' holds NaN")
    cases["norm"] = (_rewrite(good_policy, tmp_path / "ln.npz", norm_0_scale=None), "norm_0")
    cases["actions"] = (_rewrite(good_policy, tmp_path / "a.npz", {"num_actions": 35}), "num_actions 35")
    cases["no_meta"] = (_rewrite(good_policy, tmp_path / "nm.npz", metadata=None), "no 'metadata'")
    cases["bad_json"] = (_rewrite(good_policy, tmp_path / "bj.npz", metadata=np.array("{not json")), "not valid JSON")
    for name, (path, message) in cases.items():
        with pytest.raises(PolicyFileError, match=message):
            load_policy(path)
    # The good file is still good, and loading is NumPy only (no pickle).
    assert load_policy(good_policy).num_actions == 36


def test_policy_file_that_is_a_single_npy_array(tmp_path):
    path = tmp_path / "policy.npz"
    with path.open("wb") as f:
        np.save(f, np.zeros(3, np.float32))
    with pytest.raises(PolicyFileError):      # any other exception, or none, fails the test
        load_policy(path)


def test_policy_metadata_that_is_not_an_object(good_policy, tmp_path):
    path = _rewrite(good_policy, tmp_path / "p.npz", metadata=np.array("[1, 2]"))
    with pytest.raises(PolicyFileError):
        load_policy(path)


# --------------------------------------------------------------------------------------------
# Config errors and the driver's refusals
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("train, field, text", [
    ({"trace": "sideways"}, "train.trace", "forward"),
    ({"trace_kind": "dutch"}, "train.trace_kind", "replacing"),
    ({"control": "sarsa"}, "train.control", "on_policy"),
    ({"target": "soft"}, "train.target", "polyak"),
    ({"num_envs": 64, "num_minibatches": 3}, "train.num_minibatches", "64"),
    ({"gamma": 1.5}, "train.gamma", "[0, 1]"),
    ({"lam": -0.1}, "train.lam", ">= 0"),
    ({"budget_env_steps": 0, "budget_episodes": 0}, "train.budget", "budget"),
    ({"budget_env_steps": -5}, "train.budget_env_steps", ">= 0"),
    ({"learning_rate": 1e-3}, "train.learning_rate", "unknown field"),
    ({"eps_start": 0.1, "eps_end": 0.5}, "train.eps_end", "eps_start"),
    ({"hidden": [64, 0]}, r"train.hidden\[1\]", "> 0"),
    ({"hidden": [64.5]}, r"train.hidden\[0\]", "integer"),
    ({"hidden": "64"}, "train.hidden", "list"),
    ({"num_envs": 0}, "train.num_envs", "> 0"),
    ({"lr": 0.0}, "train.lr", "> 0"),
    ({"layer_norm": "yes"}, "train.layer_norm", "true or false"),
    ({"eps_decay_fraction": 0.0}, "train.eps_decay_fraction", "> 0"),
    ({"target_period": 2.5}, "train.target_period", "integer"),
])
def test_train_config_errors_name_the_field(train, field, text):
    raw = tiny_raw()
    raw["train"].update(train)
    with pytest.raises(ConfigError, match=field) as info:
        config_from_dict(raw)
    assert str(info.value).startswith(field.replace("\\", "").split("[")[0])
    assert text in str(info.value)


def test_train_config_round_trips_through_toml(tmp_path):
    cfg = tiny_config(trace="backward", trace_kind="replacing", control="on_policy", target="polyak",
                      hidden=[7, 5], budget_episodes=100)
    path = tmp_path / "c.toml"
    path.write_text(config_to_toml(cfg))
    assert load_config(path) == cfg
    assert cfg.train.hidden == (7, 5) and cfg.train.trace_kind == "replacing"


def test_run_training_refuses_to_overwrite_or_mix_runs(driver_runs, tmp_path):
    cfg = driver_runs["cfg"]
    run = tmp_path / "run"
    shutil.copytree(driver_runs["part"], run)
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    with pytest.raises(ConfigError, match="already holds a run.*--resume"):
        driver.run_training(cfg, run, seed=SEED, progress=False)
    with pytest.raises(ConfigError, match="config differs"):
        driver.run_training(tiny_config(lr=5e-4), run, seed=SEED, resume=True, progress=False)
    with pytest.raises(ConfigError, match="--seed 3"):
        driver.run_training(cfg, run, seed=SEED + 1, resume=True, progress=False)
    with pytest.raises(ConfigError, match="no checkpoint to resume from"):
        driver.run_training(cfg, tmp_path / "empty", seed=SEED, resume=True, progress=False)
    # Nothing was touched.
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before
    # A run made on another number of devices (different random streams) is not resumed here.
    from flax import serialization

    from jaxexo.storage.checkpoint import pack_checkpoint, unpack_checkpoint

    raw = serialization.msgpack_restore(unpack_checkpoint((run / driver.CHECKPOINT).read_bytes(), "ckpt"))
    raw["book"]["devices"] = 2
    (run / driver.CHECKPOINT).write_bytes(pack_checkpoint(serialization.msgpack_serialize(raw)))
    with pytest.raises(ConfigError, match="2 device"):
        driver.run_training(cfg, run, seed=SEED, resume=True, progress=False)


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------


def test_cli_train_writes_the_run_directory(background):
    """``python -m jaxexo.cli train CONFIG --out DIR --quiet --seed 3``: the background reference run
    (on one CPU device, so that the in-process driver tests can compare with it bit for bit)."""
    ref = background["reference"]
    stdout, stderr = ref.wait()
    for name in ("config.toml", "metrics.jsonl", "policy.npz", "training_curve.png", "eval.json",
                 driver.CHECKPOINT, driver.BOOKKEEPING):
        assert (ref.out / name).is_file(), name
    assert load_config(ref.out / "config.toml") == load_config(ref.cfg_path) == ref.cfg
    assert len((ref.out / "metrics.jsonl").read_text().splitlines()) == 3
    res = json.loads((ref.out / "eval.json").read_text())
    assert res["env_steps"] == TINY_UPDATES * TINY_N * TINY_T and res["seed"] == SEED and res["devices"] == 1
    assert sum(v["n"] for v in res["by_obstacle"].values()) == TINY_TRAIN["eval_episodes"]
    assert load_policy(ref.out / "policy.npz").num_actions == 36
    assert f"{res['env_steps']:,} env steps" in stdout and "policy.npz" in stdout
    assert "\r" not in stderr and "it/s" not in stderr   # --quiet: no progress bar


def test_cli_train_bad_config_exits_2_naming_the_field(tmp_path):
    cfg_path = tmp_path / "bad.toml"
    cfg_path.write_text('[train]\ncontrol = "sarsa"\n')
    r = subprocess.run(_cli_cmd("train", cfg_path, "--out", tmp_path / "run", "--quiet"), capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2
    assert "train.control" in r.stderr and "sarsa" in r.stderr
    assert not (tmp_path / "run" / "policy.npz").exists()
