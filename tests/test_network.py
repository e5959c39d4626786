"""The Q-network (jaxexo.train.network)."""

from __future__ import annotations

import numpy as np
import pytest

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)


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
    assert np.abs(leaves(g_net)[1]).max() > 0  # dense_0's kernel gradient is not trivially zero
