"""The Q-network (thesis 2.3.5, Fig. 2.2): observation -> 64 -> 32 -> 32 -> 32 -> 36, ReLU."""

from __future__ import annotations

from typing import Sequence

import flax.linen as nn
import jax.numpy as jnp


class QNetwork(nn.Module):
    hidden: Sequence[int] = (64, 32, 32, 32)
    num_actions: int = 36
    layer_norm: bool = False

    @nn.compact
    def __call__(self, x):
        for i, h in enumerate(self.hidden):
            x = nn.Dense(h, name=f"dense_{i}")(x)
            if self.layer_norm:
                x = nn.LayerNorm(name=f"norm_{i}")(x)
            x = nn.relu(x)
        return nn.Dense(self.num_actions, name="out")(x)


def dense_layers(params) -> list[tuple[jnp.ndarray, jnp.ndarray]]:
    """(kernel, bias) of each Dense layer in order; LayerNorm (scale, bias) come from norm_layers."""
    p = params["params"]
    names = sorted([k for k in p if k.startswith("dense_")], key=lambda k: int(k.split("_")[1])) + ["out"]
    return [(p[n]["kernel"], p[n]["bias"]) for n in names]


def norm_layers(params) -> list[tuple[jnp.ndarray, jnp.ndarray]]:
    p = params["params"]
    names = sorted([k for k in p if k.startswith("norm_")], key=lambda k: int(k.split("_")[1]))
    return [(p[n]["scale"], p[n]["bias"]) for n in names]
