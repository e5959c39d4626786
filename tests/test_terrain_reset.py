"""Procedural terrain in the config ([layout] terrain) and in reset: the table is parsed and
validated at load time (errors name the field), reset draws the families' outlines and placements
from the key (pure JAX, jit and vmap), and the NumPy tools draw the very same scenes for a seed
(jaxexo.physics.scenarios, the one scenario generator)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict, numpy_params, views
from jaxexo.config.toml_io import config_to_toml
from jaxexo.physics import geometry, scenarios, terrain

from conftest import legacy_raw

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.env import ExoStepEnv  # noqa: E402

TERRAIN = {"start_shift": [0.0, 0.12], "step_length": [0.55, 0.85]}


def _cfg(**terrain_kw):
    return config_from_dict(legacy_raw({"layout": {"terrain": {**TERRAIN, **terrain_kw}}}))


# --------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------


def test_terrain_table_parses_defaults_and_roundtrips():
    cfg = _cfg()
    t = cfg.layout.terrain
    assert (
        t.families == terrain.TRAIN_FAMILIES
        and t.start_shift == (0.0, 0.12)
        and t.step_length == (0.55, 0.85)
    )
    assert cfg.outline_vertices == terrain.K_MAX
    again = config_from_dict(__import__("tomllib").loads(config_to_toml(cfg)))
    assert again == cfg
    off = config_from_dict(legacy_raw({}))
    assert off.layout.terrain is None
    assert config_from_dict(__import__("tomllib").loads(config_to_toml(off))).layout.terrain is None
    # static settings tell configs with and without terrain apart (different param shapes)
    from jaxexo.config import static_settings

    assert static_settings(cfg) != static_settings(off)


@pytest.mark.parametrize(
    "terrain_raw, field",
    [
        ({"families": ["pole"]}, "layout.terrain.families"),  # held out for the benchmark
        ({"families": ["hexagon"]}, "layout.terrain.families"),
        ({"colour": 1}, "layout.terrain.colour"),
        ({"weights": [1.0, 2.0]}, "layout.terrain.weights"),
        (
            {"step_length": [0.55, 0.60]},
            "layout.terrain.step_length",
        ),  # too short for the widest family
        ({"start_shift": [0.1, 0.0]}, "layout.terrain.start_shift"),
        ({"pivot": ["sideways"]}, "layout.terrain.pivot"),
        ({"near_margin": -0.01}, "layout.terrain.near_margin"),
        ("yes", "layout.terrain"),
    ],
)
def test_bad_terrain_is_refused_naming_the_field(terrain_raw, field):
    with pytest.raises(ConfigError) as e:
        config_from_dict(legacy_raw({"layout": {"terrain": terrain_raw}}))
    assert str(e.value).startswith(field), str(e.value)


def test_terrain_needs_room_for_its_outlines_and_a_small_enough_step():
    with pytest.raises(ConfigError, match=r"^env\.max_vertices"):
        config_from_dict(legacy_raw({"env": {"max_vertices": 8}, "layout": {"terrain": TERRAIN}}))
    assert (
        config_from_dict(
            legacy_raw({"env": {"max_vertices": 16}, "layout": {"terrain": TERRAIN}})
        ).outline_vertices
        == 16
    )
    with pytest.raises(ConfigError, match=r"^env\.step_size"):
        config_from_dict(legacy_raw({"env": {"step_size": 0.07}, "layout": {"terrain": TERRAIN}}))
    with pytest.raises(ConfigError, match=r"^env\.bounds_y"):
        config_from_dict(
            legacy_raw({"env": {"bounds_y": [-0.3, 0.9]}, "layout": {"terrain": TERRAIN}})
        )


def test_test_config_drops_the_terrain():
    assert views.test_config(_cfg()).layout.terrain is None


# --------------------------------------------------------------------------------------------
# Reset and the NumPy tools: one generator
# --------------------------------------------------------------------------------------------


def _jax_scenes(cfg, seed, n):
    env = ExoStepEnv(cfg)
    keys = jnp.stack([jnp.asarray([seed, i], dtype=jnp.uint32) for i in range(n)])
    return env, jax.jit(jax.vmap(env.sample_layout, (0, None)))(keys, env.default_params)


@pytest.mark.parametrize(
    "terrain_kw",
    [{}, {"families": ["polyline", "wedge"], "weights": [1.0, 3.0], "pivot": ["between"]}],
)
def test_reset_draws_the_numpy_tools_scenes(terrain_kw):
    """The env evaluates only its config's families (a static subset); the NumPy tools evaluate
    every family: the same scenes."""
    cfg = _cfg(**terrain_kw)
    t = cfg.layout.terrain
    n = 64
    _, lj = _jax_scenes(cfg, 11, n)
    ln = scenarios.scenario_layouts(np, numpy_params(cfg), 11, n)
    np.testing.assert_array_equal(np.asarray(lj.kind), ln.kind)
    np.testing.assert_array_equal(np.asarray(lj.pivot_kind), ln.pivot_kind)
    for k in ("outline", "shape", "center_y", "width", "height", "start_y", "goal_y", "pivot_y"):
        np.testing.assert_allclose(np.asarray(getattr(lj, k)), getattr(ln, k), atol=1e-6, err_msg=k)
    # the NumPy tools' scenarios are these scenes, as Obstacles of the same outline
    from jaxexo.inference.scenarios import training_scenarios

    sc = training_scenarios(cfg, 12, seed=11)
    pivots = [i for i, w in enumerate(t.pivot) if w > 0]
    lc = scenarios.scenario_layouts(
        np, numpy_params(cfg), 11, 12, cycle=True, kinds=list(range(len(t.families))), pivots=pivots
    )
    for i, s in enumerate(sc):
        assert s.kind == terrain.FAMILY_NAMES[int(lc.kind[i])]
        assert s.obstacle.width == pytest.approx(float(lc.width[i]), abs=1e-6)
        assert s.obstacle.height == pytest.approx(float(lc.height[i]), abs=1e-6)
        assert s.step_length == pytest.approx(float(lc.goal_y[i] - lc.start_y[i]), abs=1e-6)
    assert {s.kind for s in sc} == set(t.families)
    assert {terrain.FAMILY_NAMES[k] for k in np.asarray(lj.kind)} == set(t.families)


def test_reset_draws_every_training_family_and_pivot_within_the_ranges():
    cfg = _cfg()
    env = ExoStepEnv(cfg)
    n = 2000
    obs, st = jax.jit(jax.vmap(env.reset, (0, None)))(
        jax.random.split(jax.random.PRNGKey(5), n), env.default_params
    )
    lay = jax.tree.map(np.asarray, st.layout)
    assert np.isfinite(np.asarray(obs)).all()
    names = {terrain.FAMILY_NAMES[k] for k in lay.kind}
    assert names == set(terrain.TRAIN_FAMILIES)  # never a held-out family
    assert set(lay.pivot_kind) == {0, 1, 2}
    fl = cfg.kinematics.foot_length
    L = lay.goal_y - lay.start_y
    assert lay.start_y.min() >= 0.0 and lay.start_y.max() <= 0.12 + 1e-6
    assert lay.start_y.max() > 0.11 and lay.start_y.min() < 0.01
    assert L.min() >= 0.55 - 1e-6 and L.max() <= 0.85 + 1e-6
    assert (
        0.02 <= lay.width.min()
        and lay.width.max() <= 0.40
        and 0.02 <= lay.height.min()
        and lay.height.max() <= 0.30
    )
    # independent of place(): the outline's own extents lie in the gap between the toe and the goal
    ys, zs = lay.outline[..., 0], lay.outline[..., 1]
    assert (ys.min(-1) >= lay.start_y + fl + terrain.NEAR_MARGIN - 1e-5).all()
    assert (ys.max(-1) <= lay.goal_y - terrain.FAR_MARGIN + 1e-5).all()
    np.testing.assert_allclose(ys.max(-1) - ys.min(-1), lay.width, atol=1e-5)
    np.testing.assert_allclose(zs.max(-1), lay.height, atol=1e-6)
    # "anywhere the gap allows": the obstacle's near edge is sometimes right at the toe, sometimes far
    slack = ys.min(-1) - (lay.start_y + fl + terrain.NEAR_MARGIN)
    room = (lay.goal_y - terrain.FAR_MARGIN) - (lay.start_y + fl + terrain.NEAR_MARGIN) - lay.width
    assert (slack <= room + 1e-5).all() and (slack / np.maximum(room, 1e-9)).max() > 0.95
    assert (slack / np.maximum(room, 1e-9)).min() < 0.05


def test_observed_shape_matches_a_dense_reference():
    """The observation's height profile of a terrain scene against Obstacle.profile heights sampled
    independently (geometry.Obstacle built from the unpadded outline, np.interp along its edges)."""
    cfg = config_from_dict(
        legacy_raw({"env": {"obs_profile": "shape"}, "layout": {"terrain": TERRAIN}})
    )
    ln = scenarios.scenario_layouts(np, numpy_params(cfg), 3, 60)
    frac = geometry.descriptor_fractions(cfg.env.shape_points)
    for i in range(60):
        o = terrain.unpad(ln.outline[i]).astype(np.float64)
        y = ln.center_y[i] + ln.width[i] * frac
        # np.interp of the polyline (at a vertical riser the higher end, as the descriptor's rule)
        ref = np.array(
            [
                max(
                    [np.interp(v, o[:, 0], o[:, 1])]
                    + [
                        max(a[1], b[1])
                        for a, b in zip(o[:-1], o[1:])
                        if a[0] == b[0] and abs(a[0] - v) < 1e-7
                    ]
                )
                for v in y
            ]
        )
        # float32 positions (~1e-7 m) on a steep face move a height by a few micrometres
        np.testing.assert_allclose(ln.shape[i], ref, atol=1e-4)


@pytest.mark.slow
def test_env_steps_on_terrain_scenes_and_is_deterministic():
    cfg = _cfg()
    env = ExoStepEnv(cfg)
    key = jax.random.PRNGKey(9)
    params = env.default_params

    def episode(key):
        obs, st = env.reset(key, params)

        def body(c, k):
            st, obs = c
            obs, st, r, term, trunc, info = env.step(k, st, jnp.asarray(9), params)
            return (st, obs), r

        (_, obs), r = jax.lax.scan(body, (st, obs), jax.random.split(key, 40))
        return obs, r

    a = jax.jit(jax.vmap(episode))(jax.random.split(key, 8))
    b = jax.jit(jax.vmap(episode))(jax.random.split(key, 8))
    assert np.isfinite(np.asarray(a[1])).all()
    np.testing.assert_array_equal(np.asarray(a[1]), np.asarray(b[1]))
