"""The TD(lambda) trainer (jaxexo.train.trainer): real learning on a fixed obstacle (slow), bitwise
determinism, budgets, the epsilon schedule, every trace view x control x trace kind, make_train."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.config import config_from_dict, load_config

from conftest import ROOT, legacy_raw

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.train.evaluate import make_rollout  # noqa: E402
from jaxexo.train.trainer import METRICS, Hyperparams, Trainer, make_train  # noqa: E402

from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)

# --------------------------------------------------------------------------------------------
# Learning
# --------------------------------------------------------------------------------------------

LEARN_SEED = 0
LEARN_TRAIN = {
    "num_envs": 128,
    "rollout_steps": 8,
    "num_minibatches": 4,
    "hidden": [64, 64],
    "layer_norm": True,
    "trace": "forward",
    "control": "off_policy",
    "lr": 3e-4,
    "lr_end_fraction": 0.1,
    "gamma": 0.98,
    "lam": 0.9,
    "eps_start": 1.0,
    "eps_end": 0.02,
    "eps_decay_fraction": 0.5,
    "budget_env_steps": 600_000,
}


@pytest.mark.slow
def test_trainer_learns_to_step_over_a_fixed_obstacle():
    """Watkins Q(lambda), forward view, on one fixed layout: the GREEDY policy fails the scene before
    training and clears it safely (2 cm margin, no step back) after a 600 k env-step budget, and the
    behaviour policy's success rises from ~0 (random behaviour) in the first tenth to near what
    epsilon-exploration allows in the last tenth.

    Why not "last-tenth behaviour success > 0.8" (the check before the safe-swing verdict): a safe
    swing now also forbids the heel falling back more than env.backward_tolerance (5 mm), so one
    exploratory move with a backward component (17 of the 36 directions, cos < 0, each moves the heel
    back >= 0.03 * cos(100 deg) = 5.2 mm) spoils an episode. Even a perfect greedy policy then
    succeeds with behaviour probability cap = (1 - eps * 17/36) ** steps (~0.75 at eps = 0.02 over
    ~30 steps). The old threshold, 0.8 of episodes, becomes 0.8 of that cap, the same relative
    strength; the greedy policy, which exploration does not cap, must succeed outright. Observed on
    seed 0 before this change: first tenth 0.000, last tenth 0.744."""
    from jaxexo.physics.geometry import Obstacle

    cfg = config_from_dict(
        legacy_raw(
            {
                "env": {"obs_mode": "conditioned"},
                "layout": dict(FIXED_LAYOUT),
                "reward": dict(REWARD),
                "train": LEARN_TRAIN,
            }
        )
    )
    trainer = Trainer(cfg)
    hyper = Hyperparams.from_config(cfg)
    assert trainer.num_updates == 586
    env = trainer.env
    # Greedy evaluation on the same fixed scene, built by hand: it is the scene training saw.
    layout = env.layout_for(
        Obstacle.named("base1"), pivot="obstacle", start_y=0.0, step_length=0.70
    )
    obs_fixed, _ = env.init_state(layout, env.default_params)
    obs_reset, _ = env.reset(jax.random.PRNGKey(1), env.default_params)
    np.testing.assert_allclose(obs_fixed, obs_reset, atol=1e-6)
    greedy = jax.jit(make_rollout(env, trainer.net.apply, cfg.env.max_steps))

    ts = jax.jit(trainer.init)(jax.random.PRNGKey(LEARN_SEED), hyper)
    before = greedy(ts.params, layout, env.default_params)
    assert not bool(before.success), (
        "the untrained greedy policy already clears the scene: nothing to learn"
    )
    ts, m = jax.jit(trainer.run, static_argnums=2)(ts, hyper, trainer.num_updates)
    m = metric_array(m)
    assert int(trainer.env_steps(ts)) == trainer.num_updates * 128 * 8
    tenth = len(m) // 10

    def rate(rows):
        assert rows[:, COL["episodes"]].sum() >= 200
        return rows[:, COL["successes"]].sum() / rows[:, COL["episodes"]].sum()

    first, last = rate(m[:tenth]), rate(m[-tenth:])
    assert m[-1, COL["epsilon"]] == pytest.approx(0.02)
    out = greedy(ts.params, layout, env.default_params)
    assert bool(out.reached) and bool(out.success), {
        k: np.asarray(v).tolist() for k, v in vars(out).items()
    }
    assert int(out.steps) < cfg.env.max_steps
    steps = int(out.steps)
    backward = int(np.sum(np.asarray(env.default_params.directions)[:, 0] < -1e-6))
    assert backward == 17
    cap = (1.0 - 0.02 * backward / 36) ** steps
    assert first < 0.05, (first, last, cap)
    assert last > 0.8 * cap, (first, last, cap, steps)


# --------------------------------------------------------------------------------------------
# Determinism, views and controls, make_train
# --------------------------------------------------------------------------------------------


def test_same_seed_is_bitwise_deterministic_and_seeds_differ(tiny):
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    a, ma = run(init(jax.random.PRNGKey(5), hyper), hyper, 2)
    b, mb = run(init(jax.random.PRNGKey(5), hyper), hyper, 2)
    c, mc = run(init(jax.random.PRNGKey(6), hyper), hyper, 2)
    assert trees_equal(a.params, b.params) and trees_equal(a.opt_state, b.opt_state)
    assert trees_equal(a, b)
    np.testing.assert_array_equal(metric_array(ma), metric_array(mb))
    assert not np.array_equal(leaves(a.params)[0], leaves(c.params)[0])
    assert not np.array_equal(metric_array(ma), metric_array(mc))
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
        assert np.all(metric_array(m)[:, COL["env_steps"]] == TINY_N * TINY_T)
    assert int(ts.update) == TINY_UPDATES and not bool(jax.jit(tiny["trainer"].active)(ts, hyper))
    ts2, m2 = run(ts, hyper, 2)
    assert trees_equal(ts, ts2)
    assert np.all(metric_array(m2) == 0)


def test_epsilon_schedule(tiny):
    # Linear from eps_start to eps_end over eps_decay_fraction (0.5) of the 6-update budget.
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    ts, m = run(init(jax.random.PRNGKey(1), hyper), hyper, 2)
    _, m2 = run(ts, hyper, 2)
    eps = np.concatenate([metric_array(m)[:, COL["epsilon"]], metric_array(m2)[:, COL["epsilon"]]])
    expect = [0.02 + 0.98 * max(0.0, 1 - (k / TINY_UPDATES) / 0.5) for k in range(4)]
    np.testing.assert_allclose(eps, expect, rtol=1e-5)


def test_state_types_are_stable_across_updates(tiny):
    init, run, hyper = tiny["init"], tiny["run"], tiny["hyper"]
    ts0 = init(jax.random.PRNGKey(5), hyper)
    ts1, _ = run(ts0, hyper, 2)
    assert avals(ts1) == avals(ts0)


COMBOS = [
    ("backward", "off_policy", "accumulating"),  # the tiny config
    ("backward", "off_policy", "replacing"),
    ("backward", "on_policy", "accumulating"),
    ("backward", "on_policy", "replacing"),  # through make_train, vmapped over 2 seeds
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
    start = jax.random.split(
        jax.random.PRNGKey(0), 2
    )  # make_train: both keys; the others: the first
    hyper = tiny["hyper"]
    fwd_init = Trainer(combo_config(COMBOS[-1])).init
    starts = {
        "backward": tiny["init"](start[0], hyper),
        "forward": fast_compile(fwd_init, start[0], hyper)(start[0], hyper),
    }

    def one(combo):
        ts0 = starts[combo[0]]
        if combo == COMBOS[0]:
            run = lambda ts, hyper: tiny["run"](ts, hyper, COMBO_UPDATES)  # noqa: E731
        else:
            run = fast_compile(
                Trainer(combo_config(combo)).run, ts0, hyper, COMBO_UPDATES, static_argnums=2
            )
        ts, m = run(ts0, hyper)
        return combo, {"hyper": hyper, "run": run, "ts0": ts0, "ts": ts, "m": metric_array(m)}

    def vmapped_make_train(combo):
        # The whole 6-update budget in one program, per seed.
        ts, m = fast_compile(
            jax.vmap(make_train(combo_config(combo)), in_axes=(0, None)), start, hyper
        )(start, hyper)
        first = jax.tree.map(lambda x: x[0], ts)
        return combo, {
            "ts0": starts["backward"],
            "ts": first,
            "m": metric_array(m)[0],
            "vmapped": (ts, metric_array(m)),
        }

    runs = dict(one(c) for c in COMBOS if c != COMBOS[3])
    runs.update([vmapped_make_train(COMBOS[3])])
    return runs


@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(c) for c in COMBOS])
@pytest.mark.slow  # compiles every trace view x control x trace kind (~1 min)
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


@pytest.mark.slow  # compiles every trace view x control x trace kind (~1 min)
def test_controls_and_trace_kinds_are_different_algorithms(compiled_runs):
    # From the same initial state and keys: accumulating vs replacing, Watkins vs SARSA differ.
    final = {c: leaves(compiled_runs[c]["ts"].params)[0] for c in COMBOS[:3]}
    assert not np.array_equal(final[COMBOS[0]], final[COMBOS[1]])
    assert not np.array_equal(final[COMBOS[0]], final[COMBOS[2]])


@pytest.mark.parametrize("control", ["on_policy", "off_policy"])
@pytest.mark.slow  # compiles every trace view x control x trace kind (~1 min)
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


@pytest.mark.slow  # compiles every trace view x control x trace kind (~1 min)
def test_make_train_jit_vmaps_over_seeds(compiled_runs):
    ts, m = compiled_runs[COMBOS[3]]["vmapped"]
    assert m.shape == (2, TINY_UPDATES, len(METRICS))
    assert np.all(np.isfinite(m)) and all_finite(ts.params)
    np.testing.assert_array_equal(np.asarray(ts.update), [TINY_UPDATES] * 2)
    np.testing.assert_array_equal(
        Trainer(tiny_config()).env_steps(ts), [TINY_UPDATES * TINY_N * TINY_T] * 2
    )
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
        return (
            qa.mean(1),
            qa.std(1),
            greedy.reshape(n, m).mean(1),
            td_lambda.epsilon_greedy_value(q[::m], eps),
        )

    for eps in (0.0, 0.3, 1.0):
        mean, std, greedy_share, expect = (np.asarray(x) for x in mc(jax.random.PRNGKey(2), eps))
        np.testing.assert_allclose(mean, expect, atol=4 * std.max() / np.sqrt(m) + 1e-6)
        # an exploratory draw can still pick the greedy action: 1 - eps + eps / 36 of them are greedy
        np.testing.assert_allclose(
            greedy_share, 1 - eps + eps / trainer.env.num_actions, atol=0.015
        )
    assert std.max() > 0.01  # Q differs across actions: the comparison above has teeth


def test_update_breakdown_refuses_the_backward_view_naming_the_field():
    """bench_train.py --breakdown times the forward view's parts; a backward-view config is refused at
    the call, naming train.trace, before anything is compiled."""
    import dataclasses

    from benchlib.train_bench import update_breakdown

    cfg = load_config(ROOT / "configs" / "quick.toml")
    cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, trace="backward"))
    with pytest.raises(ValueError, match="train.trace"):
        update_breakdown(cfg)
