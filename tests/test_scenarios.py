"""jaxexo.physics.scenarios, the one scenario generator: its cipher against JAX's own Threefry, the
JAX environment's reset against the NumPy scenario list for a seed, and the test set that eval.json,
sweeps and ``jaxexo eval`` score, drawn identically by the JAX and the NumPy side."""

import numpy as np
import pytest

from jaxexo.config import config_from_dict, numpy_params, views
from jaxexo.physics import scenarios
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

from conftest import legacy_raw

jax = pytest.importorskip("jax")
jnp = pytest.importorskip("jax.numpy")

FIELDS = (
    "outline",
    "shape",
    "center_y",
    "width",
    "height",
    "kind",
    "pivot_kind",
    "pivot_y",
    "start_y",
    "goal_y",
)


def test_threefry_matches_jax():
    """Independent reference: JAX's own threefry_2x32 (jax.extend.random)."""
    from jax.extend.random import threefry_2x32

    rng = np.random.default_rng(0)
    for _ in range(5):
        k = rng.integers(0, 2**32, 2, dtype=np.uint32)
        x = rng.integers(0, 2**32, 2 * 64, dtype=np.uint32)
        ref = np.asarray(threefry_2x32(jnp.asarray(k), jnp.asarray(x)))
        a, b = scenarios.threefry2x32(np, k[0], k[1], x[:64], x[64:])
        np.testing.assert_array_equal(np.concatenate([a, b]), ref)


def test_uniforms_identical_in_numpy_and_jax():
    k1 = np.arange(1000, dtype=np.uint32)
    u_np = scenarios.uniforms(np, 42, k1)
    u_jx = np.asarray(jax.jit(lambda k: scenarios.uniforms(jnp, 42, k))(jnp.asarray(k1)))
    np.testing.assert_array_equal(u_np, u_jx)
    assert u_np.dtype == np.float32 and u_np.shape == (1000, scenarios.N_UNIFORMS)
    assert (u_np >= 0).all() and (u_np < 1).all()
    # Roughly uniform: every decile holds about a tenth of the 9000 numbers.
    counts = np.histogram(u_np, bins=10, range=(0, 1))[0]
    assert (np.abs(counts - 900) < 150).all()


def test_seed_words_are_jax_key_words():
    for seed in (0, 7, 12345, 2**32 - 1):
        np.testing.assert_array_equal(
            jax.random.key_data(jax.random.PRNGKey(seed)), scenarios.seed_words(seed)
        )
    with pytest.raises(ValueError, match="seed"):
        scenarios.scenario_layouts(np, numpy_params(config_from_dict(legacy_raw())), 2**32, 3)


@pytest.mark.parametrize("which", ["default", "mixed"])
def test_env_reset_draws_the_numpy_scenario_list(which, mixed_config):
    """ExoStepEnv.reset on the key words (seed, i) gives scene i of the NumPy list for seed: bit for
    bit eagerly; under jit (XLA fuses multiply-adds) the same kinds and pivots, sizes within 2 ulp."""
    from jaxexo.env import ExoStepEnv

    cfg = config_from_dict(legacy_raw()) if which == "default" else mixed_config
    env = ExoStepEnv(cfg)
    n, seed = 300, 777
    ref = scenarios.scenario_layouts(np, numpy_params(cfg), seed, n)
    key = lambda i: jax.random.wrap_key_data(jnp.stack([jnp.uint32(seed), jnp.uint32(i)]))  # noqa: E731
    for i in (0, 1, 17, 299):
        # reset_env: the reset itself, eager (gymnax's reset is the same under jit)
        _, st = env.reset_env(key(i), env.default_params)
        for f in FIELDS:
            np.testing.assert_array_equal(
                np.asarray(getattr(st.layout, f)), getattr(ref, f)[i], err_msg=f"{f}, scene {i}"
            )
    keys = jax.vmap(key)(jnp.arange(n, dtype=jnp.uint32))
    _, st = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, env.default_params)
    for f in FIELDS:
        got = np.asarray(getattr(st.layout, f))
        if f in ("kind", "pivot_kind"):
            np.testing.assert_array_equal(got, getattr(ref, f), err_msg=f)
        else:
            np.testing.assert_allclose(got, getattr(ref, f), rtol=2.5e-7, atol=0, err_msg=f)
    # Every obstacle kind and pivot condition of the mixture is drawn.
    assert set(ref.kind) == set(range(len(cfg.layout.obstacles)))
    assert set(ref.pivot_kind) == {i for i, w in enumerate(cfg.layout.pivot) if w > 0}


def test_kind_frequencies_follow_the_mixture(mixed_config):
    """Independent reference: the config's weights (not the CDF the sampler uses)."""
    cfg = mixed_config
    lay = scenarios.scenario_layouts(np, numpy_params(cfg), 5, 20000)
    w = np.array([o.weight for o in cfg.layout.obstacles], float)
    freq = np.bincount(lay.kind, minlength=len(w)) / 20000
    np.testing.assert_allclose(freq, w / w.sum(), atol=0.015)
    pw = np.array(cfg.layout.pivot, float)
    np.testing.assert_allclose(
        np.bincount(lay.pivot_kind, minlength=3) / 20000, pw / pw.sum(), atol=0.015
    )


def test_eval_test_set_is_the_numpy_test_set():
    """eval.json's layouts (jaxexo.train.evaluate.test_layouts) and ``jaxexo eval``'s scenarios
    (jaxexo.inference.scenarios.sample_scenarios) are one set for a seed."""
    from jaxexo.inference.scenarios import sample_scenarios
    from jaxexo.physics.scenarios import TEST_KINDS
    from jaxexo.train.evaluate import test_layouts

    cfg = config_from_dict(legacy_raw())
    n, seed = 60, 12345
    lay = test_layouts(views.test_config(cfg), n, seed)
    sc = sample_scenarios(cfg, n, seed)
    assert [s.kind for s in sc] == [TEST_KINDS[k] for k in np.asarray(lay.kind)]
    assert [s.kind for s in sc[:5]] == list(TEST_KINDS)
    assert [s.pivot for s in sc] == [PIVOT_CONDITIONS[k] for k in np.asarray(lay.pivot_kind)]
    f32 = lambda xs: np.asarray(xs, np.float32)  # noqa: E731
    np.testing.assert_array_equal(f32([s.obstacle.center_y for s in sc]), lay.center_y)
    np.testing.assert_array_equal(f32([s.obstacle.width for s in sc]), lay.width)
    np.testing.assert_array_equal(f32([s.obstacle.height for s in sc]), lay.height)
    np.testing.assert_array_equal(f32([s.start_y for s in sc]), lay.start_y)
    np.testing.assert_array_equal(f32([s.start_y + s.step_length for s in sc]), lay.goal_y)
    # And the JAX side drawing the same set itself agrees (kinds, pivots exactly; sizes to 2 ulp).
    tenv_params = numpy_params(views.test_config(cfg))
    jl = scenarios.scenario_layouts(jnp, tenv_params, seed, n, cycle=True)
    np.testing.assert_array_equal(np.asarray(jl.kind), lay.kind)
    np.testing.assert_allclose(np.asarray(jl.width), lay.width, rtol=2.5e-7)
