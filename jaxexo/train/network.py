"""The Q-network (thesis 2.3.5, Fig. 2.2): observation -> 64 -> 32 -> 32 -> 32 -> 36, ReLU."""

from __future__ import annotations

from typing import Sequence

import flax.linen as nn
import jax
import jax.numpy as jnp

from jaxexo.physics.actions import NUM_ACTIONS

# Inputs this narrow (the thesis observation: heel y, z) enter the first layer as a sum of scaled rows
# of its kernel instead of a matrix product: the same arithmetic, but its gradient becomes a fused
# elementwise reduction, where XLA's CPU dot for that gradient (a contraction over the whole
# minibatch into a 2 x 64 kernel) is far slower per multiply than the other layers'
# (docs/decisions.md).
NARROW_INPUT = 4


def _narrow_dot_general(
    x, kernel, dimension_numbers, precision=None, preferred_element_type=None, **kw
):
    """flax Dense's product ``x @ kernel`` (contracting x's last axis with the kernel's first)."""
    if kernel.shape[0] > NARROW_INPUT:
        return jax.lax.dot_general(
            x,
            kernel,
            dimension_numbers,
            precision=precision,
            preferred_element_type=preferred_element_type,
        )
    out = x[..., 0:1] * kernel[0]
    for i in range(1, kernel.shape[0]):
        out = out + x[..., i : i + 1] * kernel[i]
    return out


class QNetwork(nn.Module):
    hidden: Sequence[int] = (64, 32, 32, 32)
    num_actions: int = NUM_ACTIONS
    layer_norm: bool = False

    @nn.compact
    def __call__(self, x):
        for i, h in enumerate(self.hidden):
            x = nn.Dense(
                h,
                name=f"dense_{i}",
                dot_general=_narrow_dot_general if i == 0 else jax.lax.dot_general,
            )(x)
            if self.layer_norm:
                x = nn.LayerNorm(name=f"norm_{i}")(x)
            x = nn.relu(x)
        return nn.Dense(self.num_actions, name="out")(x)


def dense_layers(params) -> list[tuple[jnp.ndarray, jnp.ndarray]]:
    """(kernel, bias) of each Dense layer in order; LayerNorm (scale, bias) come from norm_layers."""
    p = params["params"]
    names = sorted([k for k in p if k.startswith("dense_")], key=lambda k: int(k.split("_")[1])) + [
        "out"
    ]
    return [(p[n]["kernel"], p[n]["bias"]) for n in names]


def norm_layers(params) -> list[tuple[jnp.ndarray, jnp.ndarray]]:
    p = params["params"]
    names = sorted([k for k in p if k.startswith("norm_")], key=lambda k: int(k.split("_")[1]))
    return [(p[n]["scale"], p[n]["bias"]) for n in names]
