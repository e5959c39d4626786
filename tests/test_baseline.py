"""The thesis-style baseline trainer (benchlib.thesis_baseline): its lambda-returns agree with
jaxexo's, replay windows stay inside episodes, its NumPy environment steps exactly like the JAX one,
and (with PyTorch installed) the learner is deterministic and scored through the same network."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jaxexo.config import load_config

from benchlib.thesis_baseline import ReplayBuffer, truncated_lambda_returns
from conftest import ROOT, get_mixed_config

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.env import ExoStepEnv  # noqa: E402
from jaxexo.env.exo_step import Layout  # noqa: E402
from jaxexo.train import td_lambda  # noqa: E402

from benchlib.thesis_baseline import NumpyExoEnv, layout_pool  # noqa: E402


def test_truncated_lambda_returns_equal_jaxexos_lambda_returns():
    rng = np.random.default_rng(0)
    B, H, gamma, lam = 64, 8, 0.97, 0.8
    reward = rng.normal(size=(B, H))
    boot = rng.normal(size=(B, H))
    length = rng.integers(1, H + 1, size=B)
    valid = np.arange(H)[None, :] < length[:, None]
    terminated = np.zeros((B, H), bool)
    ends = rng.random(B) < 0.5  # half the windows end with the goal, the rest are cut short
    terminated[np.arange(B), length - 1] = ends
    cont = rng.random((B, H)) < 0.7  # Watkins cuts
    got = truncated_lambda_returns(reward, boot, terminated, valid, cont, gamma, lam)
    for L in np.unique(length):
        rows = np.flatnonzero(length == L)  # jaxexo's rollouts are time-major: (L, rows)
        col = lambda x: jnp.asarray(x[rows, :L].T, jnp.float32)  # noqa: E731
        ref = td_lambda.lambda_returns(
            col(reward),
            col(boot),
            col(terminated),
            jnp.zeros((L, len(rows)), bool),
            col(cont),
            gamma,
            lam,
        )
        np.testing.assert_allclose(got[rows], np.asarray(ref[0]), rtol=1e-5, atol=1e-5)
    # lambda = 0 is one-step Q-learning: r + gamma * (1 - term) * boot.
    one = truncated_lambda_returns(reward, boot, terminated, valid, cont, gamma, 0.0)
    np.testing.assert_allclose(one, reward[:, 0] + gamma * (1 - terminated[:, 0]) * boot[:, 0])


def test_replay_windows_stay_inside_an_episode_and_the_written_data():
    buf = ReplayBuffer(capacity=8, obs_dim=1)
    # 11 transitions into 8 slots: episodes end at transitions 3 and 9; slots wrap around.
    for t in range(11):
        buf.add([t], 0, float(t), False, t in (3, 9), [t + 1])
    assert buf.size == 8 and buf.head == 3
    slots, valid = buf.windows(np.array([4, 7, 1]), 4)
    # slot 4 holds t=4: t=5..7 follow in the same episode (slots 5, 6, 7).
    assert buf.reward[slots[0]].tolist() == [4, 5, 6, 7] and valid[0].tolist() == [True] * 4
    # slot 7 holds t=7: t=8, t=9 (episode end) follow; t=10 belongs to the next episode.
    assert buf.reward[slots[1]][:3].tolist() == [7, 8, 9] and valid[1].tolist() == [
        True,
        True,
        True,
        False,
    ]
    # slot 1 holds t=9 (the end of its episode): nothing after it; slot 2 (t=10) is the newest.
    assert valid[2].tolist() == [True, False, False, False]
    slots, valid = buf.windows(np.array([2]), 4)
    assert valid[0].tolist() == [True, False, False, False]  # nothing written after the newest slot


# s: float32 rounding of a move's drive time near a straight knee: 2e-3 rad over the slowest drive
# (3 rad/s), about four times the ~5e-4 rad that the square-root conditioning gives.
KNEE_STRAIGHT_S = 2e-3 / 3.0


@pytest.mark.parametrize("which", ["default", "mixed_thesis_obs"])
def test_numpy_environment_steps_like_the_jax_environment(which):
    cfg = load_config(ROOT / "configs" / "default.toml")
    if which == "mixed_thesis_obs":
        m = get_mixed_config()
        cfg = dataclasses.replace(m, env=dataclasses.replace(m.env, obs_mode="thesis"))
    pool = layout_pool(cfg, 16, seed=1)
    env = NumpyExoEnv(cfg, pool, seed=0)
    jenv = ExoStepEnv(cfg)
    p = jenv.default_params
    step = jax.jit(jenv.step_env)
    rng = np.random.default_rng(0)
    steps = 0
    for _ in range(6):
        obs = env.reset()
        i = env.order[env.next - 1]
        jobs, st = jenv.init_state(
            Layout(**{k: jnp.asarray(v[i]) for k, v in pool._asdict().items() if v is not None}), p
        )
        np.testing.assert_allclose(obs, jobs, atol=1e-6)
        for _ in range(cfg.env.max_steps):
            a = int(rng.integers(36))
            obs, r, term, trunc, info = env.step(a)
            jobs, st, jr, jterm, jinfo = step(jax.random.PRNGKey(0), st, a, p)
            np.testing.assert_allclose(obs, jobs, atol=1e-5)
            # The wearer's move time (rewards.wearer_terms) differs by float32 rounding amplified at a
            # straight knee (a flexion angle grows as the square root of the leg's length deficit, so a
            # 1e-7 m rounding is ~5e-4 rad): compared at that conditioning; the rest of the reward at 1e-5.
            w, jw = np.asarray(info["wearer_terms"]), np.asarray(jinfo["wearer_terms"])
            np.testing.assert_allclose(w[1], jw[1], atol=KNEE_STRAIGHT_S)
            np.testing.assert_allclose(w[0], jw[0], atol=1e-6)
            tc = cfg.reward.time_cost
            np.testing.assert_allclose(
                r - tc * w[1], float(jr) - tc * float(jw[1]), rtol=1e-5, atol=1e-5
            )
            np.testing.assert_allclose(info["traj_terms"], jinfo["traj_terms"], atol=1e-5)
            assert term == bool(jterm) and bool(info["collision"]) == bool(jinfo["collision"])
            steps += 1
            if term or trunc:
                break
    assert steps > 100


def _learner(cfg, seed):
    from benchlib.baseline_bench import make_baseline

    return make_baseline(cfg, layout_pool(cfg, 64, seed=2), eps_decay_steps=300, seed=seed)


def test_torch_learner_is_deterministic_and_exports_the_same_network():
    torch = pytest.importorskip("torch")
    from jaxexo.train.network import QNetwork

    cfg = load_config(ROOT / "configs" / "default.toml")
    a, b = _learner(cfg, 0), _learner(cfg, 0)
    ra = a.train(env_steps=400)
    b.train(env_steps=400)
    assert ra["env_steps"] == 400 and ra["updates"] == 400 - a.s.learning_starts + 1
    for pa, pb in zip(a.q.parameters(), b.q.parameters()):
        assert torch.equal(pa, pb)
    # Training moved the weights away from the target copy taken at the start.
    assert any(
        not torch.equal(p, t) for p, t in zip(a.q.parameters(), _learner(cfg, 0).q.parameters())
    )
    # The exported flax tree gives the torch network's Q-values (the validator scores this).
    obs = np.stack([a.env.reset() for _ in range(5)]).astype(np.float32)
    net = QNetwork(hidden=cfg.train.hidden, num_actions=36, layer_norm=cfg.train.layer_norm)
    q_flax = np.asarray(net.apply(jax.tree.map(jnp.asarray, a.export_flax_params()), obs))
    with torch.no_grad():
        q_torch = a.q(torch.from_numpy(obs)).numpy()
    np.testing.assert_allclose(q_flax, q_torch, rtol=1e-4, atol=1e-4)


def test_torch_learner_targets_terminal_transitions_with_their_reward():
    pytest.importorskip("torch")
    cfg = load_config(ROOT / "configs" / "default.toml")
    lr = _learner(cfg, 1)
    lr.train(env_steps=200)
    buf = lr.buffer
    term = np.flatnonzero(buf.terminated[: buf.size])
    trunc = np.flatnonzero(buf.done[: buf.size] & ~buf.terminated[: buf.size])
    idx = np.concatenate([term, trunc])
    if len(term):
        np.testing.assert_allclose(lr.targets(term), buf.reward[term], rtol=1e-6)
    # A truncated last step bootstraps on its final observation with the target network.
    if len(trunc):
        import torch

        with torch.no_grad():
            boot = lr.q_target(torch.from_numpy(buf.next_obs[trunc])).max(-1).values.numpy()
        np.testing.assert_allclose(
            lr.targets(trunc), buf.reward[trunc] + lr.gamma * boot, rtol=1e-5, atol=1e-6
        )
    assert len(idx) > 0
