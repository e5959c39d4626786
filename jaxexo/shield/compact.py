"""Compute an expensive per-item function only where a batch needs it, under jit and vmap: the picked
items in rounds of a fixed buffer, equal to ``jnp.where(pick, fn(all items), default)``. Used by the
shield's JAX mask and the environment's auto-reset; the method: docs/safety.md, "The shield".
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp


def buffer_size(total: int, fraction: float) -> int:
    """Items per round: ``fraction`` of the batch, at least one, at most all of it."""
    return max(1, min(total, math.ceil(fraction * total)))


def compacted(pick, fn, default, buffer: int):
    """``default`` (a pytree of arrays with leading axis ``pick.shape[0]``) with the rows where
    ``pick`` holds replaced by ``fn(idx)``: ``fn`` takes (buffer,) int32 item indices (padding
    repeats a valid index; its rows are dropped) and returns the same pytree with leading axis
    ``buffer``."""
    total = pick.shape[0]
    m = buffer
    count = jnp.sum(pick, dtype=jnp.int32)
    # The picked items' indices first, in order; padded so that every round's slice is in bounds.
    order = jnp.nonzero(pick, size=total, fill_value=total)[0].astype(jnp.int32)
    order = jnp.concatenate([order, jnp.full((m,), total, jnp.int32)])

    def round_(r, out):
        idx = jax.lax.dynamic_slice(order, (r * m,), (m,))
        rows = fn(jnp.minimum(idx, total - 1))
        return jax.tree.map(lambda o, v: o.at[idx].set(v, mode="drop"), out, rows)

    return jax.lax.fori_loop(0, (count + m - 1) // m, round_, default)
