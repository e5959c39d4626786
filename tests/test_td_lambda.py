"""jaxexo.train.td_lambda: the two views of TD(lambda) (thesis 2.3.4-2.3.5, eq 2.19-2.28).

The key theory check: with a fixed linear Q(s, a) = w[a] . phi(s) + b[a] over one episode, the summed
backward-view updates sum_t delta_t e_t (eligibility traces, eq 2.22/2.26) equal the summed
forward-view updates sum_t (G_t - Q(s_t, a_t)) grad Q(s_t, a_t) with the lambda-returns of eq 2.19
(offline equivalence, Sutton & Barto 12.4), for on-policy SARSA(lambda) and Watkins Q(lambda), in
float64 to 1e-9. The traces are built with the same conventions as ``Trainer._update_backward``:
decay by gamma * lambda, reset at the episode start and (Watkins) cut when the action taken is not
greedy, *then* add the gradient of Q(s_t, a_t).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxexo.train import td_lambda

LAMBDAS = (0.0, 0.5, 0.9, 1.0)
GAMMAS = (0.5, 0.9, 1.0)


def _returns(rewards, boot, terminated, done, cont, gamma, lam):
    f = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    return np.asarray(
        td_lambda.lambda_returns(
            f(rewards),
            f(boot),
            jnp.asarray(terminated, bool),
            jnp.asarray(done, bool),
            jnp.asarray(cont, bool),
            gamma,
            lam,
        )
    )


# --------------------------------------------------------------------------------------------
# Offline equivalence of the forward and backward views
# --------------------------------------------------------------------------------------------


def _episode(seed: int, control: str, n_env=3, length=12, n_feat=5, n_act=4):
    """N independent episodes of one length, each terminated at its last step, with a fixed linear Q.

    Returns everything both views need, time first: features (L, N, D), actions, rewards, Q(s_t, a_t),
    greedy flags, bootstrap values and the gradient pytree of Q(s_t, a_t) w.r.t. {w, b}."""
    rng = np.random.default_rng(seed)
    w = rng.normal(size=(n_act, n_feat))
    b = rng.normal(size=n_act)
    phi = rng.normal(size=(length, n_env, n_feat))
    q_all = phi @ w.T + b  # (L, N, A)
    greedy_a = q_all.argmax(-1)
    # Behaviour: the greedy action 60% of the time, else any action; every episode takes at least
    # one greedy and one exploratory action in its middle so that the Watkins cut is exercised.
    actions = np.where(
        rng.uniform(size=(length, n_env)) < 0.6, greedy_a, rng.integers(0, n_act, (length, n_env))
    )
    actions[length // 2] = greedy_a[length // 2]
    actions[length // 2 + 1] = (greedy_a[length // 2 + 1] + 1) % n_act
    greedy = actions == greedy_a
    assert greedy.any() and (~greedy).any()
    rewards = rng.normal(size=(length, n_env))
    q_sa = np.take_along_axis(q_all, actions[..., None], -1)[..., 0]
    # boot[t]: the value of s_{t+1}; the last step terminates, so its boot must not matter: a large
    # random value makes any leak visible.
    if control == "on_policy":
        boot = np.concatenate([q_sa[1:], 1e3 * rng.normal(size=(1, n_env))])  # Q(s', a'), eq 2.27
        cont = np.ones((length, n_env), bool)
    else:
        boot = np.concatenate(
            [q_all[1:].max(-1), 1e3 * rng.normal(size=(1, n_env))]
        )  # max_a Q(s', a), eq 2.28
        cont = greedy
    terminated = np.zeros((length, n_env), bool)
    terminated[-1] = True
    onehot = np.eye(n_act)[actions]  # (L, N, A)
    grads = {"w": onehot[..., None] * phi[:, :, None, :], "b": onehot}  # dQ/dw: phi(s) in row a
    return dict(
        rewards=rewards,
        boot=boot,
        terminated=terminated,
        cont=cont,
        greedy=greedy,
        q_sa=q_sa,
        grads=grads,
        n_env=n_env,
        length=length,
    )


def _forward_sum(ep, gamma, lam):
    """sum_t (G_t - Q(s_t, a_t)) grad Q(s_t, a_t) per environment (forward view, eq 2.19-2.20)."""
    g = td_lambda.lambda_returns(
        jnp.asarray(ep["rewards"]),
        jnp.asarray(ep["boot"]),
        jnp.asarray(ep["terminated"]),
        jnp.asarray(ep["terminated"]),
        jnp.asarray(ep["cont"]),
        gamma,
        lam,
    )
    g = np.asarray(g)
    assert g.dtype == np.float64
    err = g - ep["q_sa"]  # (L, N)
    return {k: np.einsum("tn,tn...->n...", err, v) for k, v in ep["grads"].items()}


def _backward_sum(ep, gamma, lam, control, kind="accumulating"):
    """sum_t delta_t e_t per environment (backward view, eq 2.22, 2.26), with the trainer's
    conventions: keep = not episode start and (Watkins) a_t greedy; decay, then add grad Q(s_t, a_t).
    Also returns the sum over t of ``trace_update_direction`` (the mean over environments)."""
    n = ep["n_env"]
    rng = np.random.default_rng(1)
    # Stale traces from a previous episode: the episode start must wipe them.
    traces = {k: jnp.asarray(rng.normal(size=v.shape[1:])) for k, v in ep["grads"].items()}
    total = {k: np.zeros(v.shape[1:]) for k, v in ep["grads"].items()}
    mean_total = {k: np.zeros(v.shape[2:]) for k, v in ep["grads"].items()}
    for t in range(ep["length"]):
        fresh = np.full(n, t == 0)
        keep = ~fresh & (ep["greedy"][t] if control == "off_policy" else True)
        traces = td_lambda.decay_traces(traces, gamma, lam, jnp.asarray(keep))
        traces = td_lambda.add_gradient(
            traces, {k: jnp.asarray(v[t]) for k, v in ep["grads"].items()}, kind
        )
        delta = (
            ep["rewards"][t] + gamma * (1.0 - ep["terminated"][t]) * ep["boot"][t] - ep["q_sa"][t]
        )
        for k in total:
            e = np.asarray(traces[k])
            assert e.dtype == np.float64
            total[k] += delta.reshape((n,) + (1,) * (e.ndim - 1)) * e
        direction = td_lambda.trace_update_direction(traces, jnp.asarray(delta))
        for k in mean_total:
            mean_total[k] += np.asarray(direction[k])
    return total, mean_total


@pytest.mark.parametrize("control", ["on_policy", "off_policy"])
@pytest.mark.parametrize("gamma", GAMMAS)
@pytest.mark.parametrize("lam", LAMBDAS)
def test_offline_equivalence_of_forward_and_backward_views(control, gamma, lam):
    with jax.enable_x64(True):
        for seed in range(3):
            ep = _episode(seed, control)
            fwd = _forward_sum(ep, gamma, lam)
            bwd, bwd_mean = _backward_sum(ep, gamma, lam, control)
            for k in fwd:
                scale = np.abs(fwd[k]).max()
                assert scale > 1e-3  # a real, non-trivial update
                np.testing.assert_allclose(bwd[k], fwd[k], rtol=1e-9, atol=1e-12 * scale)
                np.testing.assert_allclose(
                    bwd_mean[k], fwd[k].mean(0), rtol=1e-9, atol=1e-12 * scale
                )


def test_offline_equivalence_is_sensitive_to_the_watkins_cut():
    """Sanity check of the test above: the same episode without the cut on either side differs, and
    so does an off-policy forward view paired with uncut traces."""
    gamma, lam = 0.9, 0.9
    with jax.enable_x64(True):
        ep = _episode(0, "off_policy")
        fwd = _forward_sum(ep, gamma, lam)
        bwd_uncut, _ = _backward_sum(ep, gamma, lam, "on_policy")
        assert not np.allclose(bwd_uncut["w"], fwd["w"], rtol=1e-6)
        # Replacing traces are a different algorithm: they must not match accumulating ones here.
        bwd_repl, _ = _backward_sum(ep, gamma, lam, "off_policy", kind="replacing")
        assert not np.allclose(bwd_repl["w"], fwd["w"], rtol=1e-6)


@pytest.mark.parametrize("gamma", GAMMAS)
@pytest.mark.parametrize("lam", (0.0, 0.3, 0.8))
def test_lambda_returns_are_the_lambda_average_of_n_step_returns(gamma, lam):
    """Eq 2.19 literally, over one terminating episode: G^lambda_t = (1 - lambda) sum_n lambda^{n-1}
    G^{(n)}_t, the n-step returns (eq 2.17) that reach the end of the episode weighing the rest."""
    rng = np.random.default_rng(7)
    L = 9
    r, v = rng.normal(size=L), rng.normal(size=L)  # v[t]: the value of s_{t+1}
    with jax.enable_x64(True):
        term = np.zeros(L, bool)
        term[-1] = True
        g = np.asarray(
            td_lambda.lambda_returns(
                jnp.asarray(r),
                jnp.asarray(v),
                jnp.asarray(term),
                jnp.asarray(term),
                jnp.ones(L, bool),
                gamma,
                lam,
            )
        )
    for t in range(L):
        m = L - t  # steps left, the last one terminating
        g_n = [
            sum(gamma**k * r[t + k] for k in range(n)) + (gamma**n * v[t + n - 1] if n < m else 0.0)
            for n in range(1, m + 1)
        ]
        expect = (1 - lam) * sum(lam ** (n - 1) * g_n[n - 1] for n in range(1, m)) + lam ** (
            m - 1
        ) * g_n[-1]
        assert g[t] == pytest.approx(expect, rel=1e-12, abs=1e-12)


# --------------------------------------------------------------------------------------------
# lambda_returns by hand
# --------------------------------------------------------------------------------------------

R = [1.0, 2.0, 3.0, 4.0]
B = [10.0, 20.0, 30.0, 40.0]
F = [False] * 4
T = [True] * 4


def test_lambda_zero_gives_one_step_targets():
    g = _returns(R, B, F, F, T, 0.5, 0.0)
    np.testing.assert_allclose(g, [1 + 5, 2 + 10, 3 + 15, 4 + 20])
    # ...with termination: no bootstrap at the terminal step
    g = _returns(R, B, [False, True, False, False], [False, True, False, False], T, 0.5, 0.0)
    np.testing.assert_allclose(g, [6, 2, 18, 24])


def test_lambda_one_is_monte_carlo():
    # One episode terminating at its last step: the discounted sum of rewards, bootstraps ignored.
    term = [False, False, False, True]
    g = _returns(R, [123.0, -7.0, 55.0, 999.0], term, term, T, 0.5, 1.0)
    np.testing.assert_allclose(
        g, [1 + 0.5 * 2 + 0.25 * 3 + 0.125 * 4, 2 + 0.5 * 3 + 0.25 * 4, 3 + 0.5 * 4, 4]
    )


def test_lambda_one_without_termination_bootstraps_at_the_rollout_end():
    g = _returns(R, B, F, F, T, 0.5, 1.0)
    # G_3 = r_3 + gamma * boot_3 (rollout end), then Monte Carlo back to it.
    np.testing.assert_allclose(
        g, [1 + 0.5 * 2 + 0.25 * 3 + 0.125 * 24, 2 + 0.5 * 3 + 0.25 * 24, 3 + 0.5 * 24, 24]
    )


def test_intermediate_lambda_by_hand():
    gamma, lam = 0.5, 0.5
    g = _returns(R, B, F, F, T, gamma, lam)
    g3 = 4 + 0.5 * 40
    g2 = 3 + gamma * ((1 - lam) * 30 + lam * g3)
    g1 = 2 + gamma * ((1 - lam) * 20 + lam * g2)
    g0 = 1 + gamma * ((1 - lam) * 10 + lam * g1)
    np.testing.assert_allclose(g, [g0, g1, g2, g3], rtol=1e-6)


def _chain_cut_after_step_1():
    """Returns for R, B with gamma 0.5, lambda 1 when G_1 bootstraps on boot_1 alone (the chain is
    cut after step 1) and every other step chains into the next."""
    g3 = 4 + 0.5 * 40
    g2 = 3 + 0.5 * g3
    g1 = 2 + 0.5 * 20
    g0 = 1 + 0.5 * g1
    return [g0, g1, g2, g3]


def test_truncation_bootstraps_on_boot_alone_and_cuts_the_chain():
    # Step 1 is truncated (done, not terminated): G_1 = r_1 + gamma * boot_1 whatever follows;
    # step 0 still chains into G_1 (lambda = 1).
    done = [False, True, False, False]
    g = _returns(R, B, F, done, T, 0.5, 1.0)
    np.testing.assert_allclose(g, _chain_cut_after_step_1())
    # The steps after the truncation (a new episode) do not leak into G_1: change them, G_0 and G_1 stay.
    g_other = _returns([1.0, 2.0, -50.0, 80.0], [10.0, 20.0, 1e4, -1e4], F, done, T, 0.5, 1.0)
    np.testing.assert_allclose(g_other[:2], g[:2])


def test_termination_gives_no_bootstrap():
    term = [False, True, False, False]
    g = _returns(R, B, term, term, T, 0.5, 0.7)
    assert g[1] == pytest.approx(2.0)  # boot_1 = 20 is ignored
    assert g[0] == pytest.approx(1 + 0.5 * (0.3 * 10 + 0.7 * 2.0))
    # Termination without `done` set still refuses the bootstrap and the continuation.
    g_t = _returns(R, B, term, F, T, 0.5, 0.7)
    assert g_t[1] == pytest.approx(2.0)


def test_watkins_cut_uses_the_next_steps_greediness():
    # cont[2] = 0: the action at step 2 was exploratory, so G_1 bootstraps on boot_1 alone (lambda = 1),
    # while G_2 itself still chains into G_3 (cont[3] = 1).
    cont = [True, True, False, True]
    g = _returns(R, B, F, F, cont, 0.5, 1.0)
    np.testing.assert_allclose(g, _chain_cut_after_step_1())
    # cont[0] is never used (no step before the rollout's first).
    np.testing.assert_allclose(_returns(R, B, F, F, [False, True, False, True], 0.5, 1.0), g)


def test_lambda_returns_per_environment_columns():
    rng = np.random.default_rng(3)
    r, b = rng.normal(size=(6, 5)), rng.normal(size=(6, 5))
    done = rng.uniform(size=(6, 5)) < 0.3
    term = done & (rng.uniform(size=(6, 5)) < 0.5)
    cont = rng.uniform(size=(6, 5)) < 0.7
    g = _returns(r, b, term, done, cont, 0.9, 0.8)
    assert g.shape == (6, 5)
    for i in range(5):
        np.testing.assert_allclose(
            g[:, i],
            _returns(r[:, i], b[:, i], term[:, i], done[:, i], cont[:, i], 0.9, 0.8),
            rtol=1e-6,
        )


def test_lambda_returns_is_jittable_and_vmappable_over_gamma():
    f = jax.jit(jax.vmap(td_lambda.lambda_returns, in_axes=(None, None, None, None, None, 0, None)))
    g = np.asarray(
        f(
            jnp.asarray(R),
            jnp.asarray(B),
            jnp.zeros(4, bool),
            jnp.zeros(4, bool),
            jnp.ones(4, bool),
            jnp.asarray([0.0, 0.5]),
            0.0,
        )
    )
    np.testing.assert_allclose(g[0], R)
    np.testing.assert_allclose(g[1], [6, 12, 18, 24])


# --------------------------------------------------------------------------------------------
# Traces
# --------------------------------------------------------------------------------------------


def test_decay_traces_scales_and_resets_per_environment():
    tr = {"a": jnp.ones((3,)), "b": jnp.full((3, 2), 2.0), "c": jnp.full((3, 2, 4), -1.0)}
    out = td_lambda.decay_traces(tr, 0.9, 0.5, jnp.asarray([True, False, True]))
    np.testing.assert_allclose(out["a"], [0.45, 0.0, 0.45])
    np.testing.assert_allclose(out["b"], np.array([0.9, 0.0, 0.9])[:, None] * np.ones((3, 2)))
    np.testing.assert_allclose(
        out["c"], np.array([-0.45, 0.0, -0.45])[:, None, None] * np.ones((3, 2, 4))
    )
    assert out["c"].dtype == jnp.float32


def test_accumulating_trace_adds():
    e = {"w": jnp.asarray([[0.5, -1.0, 0.0]])}
    g = {"w": jnp.asarray([[1.0, 1.0, 0.0]])}
    np.testing.assert_allclose(td_lambda.add_gradient(e, g, "accumulating")["w"], [[1.5, 0.0, 0.0]])


def test_replacing_trace_reduces_to_tabular_for_one_hot_features():
    # Tabular replacing traces (Sutton & Barto 12.3): the visited pair's trace becomes 1, the others
    # keep their decayed values; accumulating would give 1 + gamma * lambda on a revisit.
    gamma, lam = 0.9, 0.8
    e = jnp.zeros((1, 3))
    visits = [0, 0, 2, 0]
    acc = e
    for s in visits:
        onehot = jax.nn.one_hot(jnp.asarray([s]), 3)
        e = td_lambda.add_gradient(
            td_lambda.decay_traces(e, gamma, lam, jnp.asarray([True])), onehot, "replacing"
        )
        acc = td_lambda.add_gradient(
            td_lambda.decay_traces(acc, gamma, lam, jnp.asarray([True])), onehot, "accumulating"
        )
    gl = gamma * lam
    np.testing.assert_allclose(e[0], [1.0, 0.0, gl], rtol=1e-6)
    np.testing.assert_allclose(acc[0], [1 + gl**2 + gl**3, 0.0, gl], rtol=1e-6)


def test_replacing_trace_signed_gradients():
    # Replace where |grad| > |e|, keep otherwise (ties keep the trace).
    e = jnp.asarray([-2.0, 0.5, 0.3, -1.0, 0.0])
    g = jnp.asarray([1.0, -1.0, 0.0, 1.0, -0.25])
    np.testing.assert_allclose(
        td_lambda.add_gradient(e, g, "replacing"), [-2.0, -1.0, 0.3, -1.0, -0.25]
    )


def test_add_gradient_rejects_unknown_kind():
    with pytest.raises(ValueError, match="trace kind.*dutch"):
        td_lambda.add_gradient(jnp.zeros(2), jnp.ones(2), "dutch")


def test_trace_update_direction_is_the_mean_of_delta_times_trace():
    rng = np.random.default_rng(0)
    e = {
        "k": rng.normal(size=(4, 2, 3)).astype(np.float32),
        "b": rng.normal(size=(4, 3)).astype(np.float32),
        "s": rng.normal(size=(4,)).astype(np.float32),
    }
    d = rng.normal(size=4).astype(np.float32)
    out = td_lambda.trace_update_direction(jax.tree.map(jnp.asarray, e), jnp.asarray(d))
    np.testing.assert_allclose(
        out["k"], np.einsum("n,nij->ij", d, e["k"]) / 4, rtol=1e-5, atol=1e-6
    )
    np.testing.assert_allclose(out["b"], np.einsum("n,nj->j", d, e["b"]) / 4, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(out["s"], (d * e["s"]).mean(), rtol=1e-5, atol=1e-6)
    assert out["k"].shape == (2, 3) and out["s"].shape == ()
    # Zero TD errors: no update, whatever the traces.
    zero = td_lambda.trace_update_direction(jax.tree.map(jnp.asarray, e), jnp.zeros(4))
    assert all(float(jnp.abs(x).max()) == 0.0 for x in jax.tree.leaves(zero))


# --------------------------------------------------------------------------------------------
# Epsilon-greedy expectation
# --------------------------------------------------------------------------------------------


def test_epsilon_greedy_value():
    q = jnp.asarray([[1.0, 2.0, 6.0], [-3.0, 0.0, 0.0]])
    np.testing.assert_allclose(td_lambda.epsilon_greedy_value(q, 0.0), [6.0, 0.0])
    np.testing.assert_allclose(td_lambda.epsilon_greedy_value(q, 1.0), [3.0, -1.0])
    np.testing.assert_allclose(
        td_lambda.epsilon_greedy_value(q, 0.3), [0.7 * 6 + 0.3 * 3, 0.3 * -1.0], rtol=1e-6
    )
    # One epsilon per row (vmapped sweeps) and a 1-D Q row.
    np.testing.assert_allclose(
        td_lambda.epsilon_greedy_value(q, jnp.asarray([0.0, 1.0])), [6.0, -1.0]
    )
    assert float(td_lambda.epsilon_greedy_value(jnp.asarray([0.0, 4.0]), 0.5)) == pytest.approx(3.0)
