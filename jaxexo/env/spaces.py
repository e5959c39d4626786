"""Observation and action spaces with the gymnax 1.0 interface: gymnax's own classes when it is
installed (its wrappers check ``isinstance``), minimal equivalents otherwise.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


class Discrete:
    def __init__(self, num_categories: int, dtype=jnp.int32):
        self.n = num_categories
        self.shape = ()
        self.dtype = dtype

    def sample(self, key):
        return jax.random.randint(key, self.shape, 0, self.n).astype(self.dtype)

    def contains(self, x):
        return jnp.logical_and(x >= 0, x < self.n)


class Box:
    def __init__(self, low, high, shape, dtype=jnp.float32):
        self.low, self.high, self.shape, self.dtype = low, high, shape, dtype

    def sample(self, key):
        low = jnp.maximum(jnp.asarray(self.low, self.dtype), -1e6)
        high = jnp.minimum(jnp.asarray(self.high, self.dtype), 1e6)
        return jax.random.uniform(key, self.shape, minval=low, maxval=high).astype(self.dtype)

    def contains(self, x):
        return jnp.all(jnp.logical_and(x >= self.low, x <= self.high))


def _gymnax_spaces():
    try:
        from gymnax.environments import spaces as gspaces
    except ImportError:
        return None
    return gspaces


def discrete(n: int):
    g = _gymnax_spaces()
    return g.Discrete(n) if g is not None else Discrete(n)


def box(low, high, shape, dtype=jnp.float32):
    g = _gymnax_spaces()
    return g.Box(low, high, shape, dtype) if g is not None else Box(low, high, shape, dtype)
