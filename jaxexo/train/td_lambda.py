"""TD(lambda) in its two views (thesis 2.3.4-2.3.5, eq 2.19-2.26), as pure functions: lambda-returns
by a reverse scan (forward view) and eligibility traces over the Q-network's parameters (backward
view), for SARSA(lambda) and Watkins Q(lambda). Arrays are over time first; ``boot``, ``terminated``,
``done`` and ``cont`` per transition as in docs/training.md, "The trainer".
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def lambda_returns(rewards, boot, terminated, done, cont, gamma, lam):
    """Lambda-returns G_t (eq 2.19, recursive form) over a rollout, by a reverse scan.

    G_t = r_t + gamma * (1 - terminated_t) * [(1 - l_t) * boot_t + l_t * G_{t+1}]
    with l_t = lam * cont_{t+1} * (1 - done_t), and at the rollout's last step G = r + gamma * boot."""
    not_term = 1.0 - terminated.astype(rewards.dtype)
    chain = 1.0 - done.astype(rewards.dtype)
    # l_t uses cont of the *next* step; the last step has no next step in the rollout.
    cont_next = jnp.concatenate([cont[1:], jnp.zeros_like(cont[:1])], axis=0).astype(rewards.dtype)
    lt = lam * cont_next * chain

    def body(g_next, x):
        r, b, nt, l = x  # noqa: E741 (l_t, as in the thesis)
        g = r + gamma * nt * ((1.0 - l) * b + l * g_next)
        return g, g

    _, g = jax.lax.scan(
        body, jnp.zeros_like(rewards[-1]), (rewards, boot, not_term, lt), reverse=True
    )
    return g


def decay_traces(traces, gamma, lam, keep):
    """e <- gamma * lam * e, zeroed where ``keep`` is 0 (episode start; Watkins cut). Per environment:
    ``keep`` has shape (N,), every leaf of ``traces`` (N, ...)."""

    def f(e):
        k = keep.reshape(keep.shape + (1,) * (e.ndim - 1)).astype(e.dtype)
        return gamma * lam * k * e

    return jax.tree.map(f, traces)


def add_gradient(traces, grads, kind: str):
    """Eq 2.22 for function approximation: accumulate the gradient of Q(s_t, a_t) into the traces.

    ``accumulating``: e + grad. ``replacing``: the elementwise generalisation of replacing traces to
    signed gradients: where |grad| exceeds |e| the trace is replaced by grad, else kept (it reduces
    to the tabular replacing trace for one-hot features)."""
    if kind == "accumulating":
        return jax.tree.map(jnp.add, traces, grads)
    if kind == "replacing":
        return jax.tree.map(lambda e, g: jnp.where(jnp.abs(g) > jnp.abs(e), g, e), traces, grads)
    raise ValueError(f"trace kind must be 'accumulating' or 'replacing', got {kind!r}")


def trace_update_direction(traces, td_errors):
    """Eq 2.26 summed over environments: mean_i delta_i * e_i (the ascent direction)."""

    def f(e):
        d = td_errors.reshape(td_errors.shape + (1,) * (e.ndim - 1)).astype(e.dtype)
        return jnp.mean(d * e, axis=0)

    return jax.tree.map(f, traces)


def epsilon_greedy_value(q, eps):
    """Expected Q under the epsilon-greedy policy: (1 - eps) max Q + eps mean Q (for SARSA where
    the next action is not known)."""
    return (1.0 - eps) * jnp.max(q, axis=-1) + eps * jnp.mean(q, axis=-1)


def restrict(q, mask):
    """Q (..., A) for bootstrapping over the admissible actions ``mask`` only (None: all): inadmissible
    entries are replaced by the admissible mean, so max Q, the epsilon-greedy expectation (an
    exploratory action is uniform over the admissible ones) and any admissible action's value read
    as over the admissible set."""
    if mask is None:
        return q
    m = mask.astype(q.dtype)
    mean = jnp.sum(q * m, axis=-1, keepdims=True) / jnp.maximum(
        jnp.sum(m, axis=-1, keepdims=True), 1.0
    )
    return jnp.where(mask, q, mean)
