"""[env] obstacle_change: training episodes whose obstacle changes at a drawn step.

Off (the default) the environment is the program it was (no state leaves, the same scenes, nothing
written to a config); on, an episode's layout switches to the changed obstacle exactly at its drawn
step, never onto the foot, and the change's geometry keeps the properties docs/training.md states
(checked against independent NumPy computations); the option's errors name it as typed."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict, numpy_params
from jaxexo.config.changes import ChangeSpec
from jaxexo.config.toml_io import config_to_toml
from jaxexo.physics import changes, geometry, scenarios, terrain

from conftest import TINY_N, TINY_T, tiny_raw

ON = {"chance": 1.0, "steps": [3, 12], "second": 0.3}


def _on(change=None, **env):
    return config_from_dict({"env": {"obstacle_change": ON if change is None else change, **env}})


# --------------------------------------------------------------------------------------------
# The option
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "value, message",
    [
        ("yes", r"^env\.obstacle_change: expected 0 \(off\), a probability in \(0, 1\]"),
        (1.5, r"^env\.obstacle_change: a probability, must be in \[0, 1\], got 1\.5"),
        (-0.1, r"^env\.obstacle_change: must be >= 0, got -0\.1"),
        ({"chance": 2}, r"^env\.obstacle_change\.chance: a probability, must be in \[0, 1\]"),
        ({"steps": [0, 4]}, r"^env\.obstacle_change\.steps\[0\]: must be >= 1, got 0"),
        ({"steps": [2.5, 4]}, r"^env\.obstacle_change\.steps\[0\]: expected an integer, got 2\.5"),
        ({"taller": [0.5, 0.1]}, r"^env\.obstacle_change\.taller: range \[lo, hi\] needs lo <= hi"),
        ({"wider": [0.0, 3.0]}, r"^env\.obstacle_change\.wider\[1\]: must be <= 2\.0, got 3\.0"),
        ({"move": [-0.3, 0.0]}, r"^env\.obstacle_change\.move\[0\]: must be >= -0\.2, got -0\.3"),
        ({"second": True}, r"^env\.obstacle_change\.second: expected a number, got True"),
        ({"taler": [0, 1]}, r"^env\.obstacle_change\.taler: unknown field \(known: chance, steps"),
        # the change must come before the episode's last step
        ({"steps": [5, 100]}, r"^env\.obstacle_change\.steps: a change at step 100 is not before "),
    ],
)
def test_errors_name_the_option_as_typed(value, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict({"env": {"obstacle_change": value}})


def test_off_is_the_default_and_is_not_written():
    """0, false and a chance of 0 are off (None); the resolved config leaves the field out then, so
    every config and policy file written before it reads the same, and one that lacks it is off."""
    from jaxexo.config import Config
    from jaxexo.storage.policy_file import policy_config

    assert Config().env.obstacle_change is None
    for off in (0, 0.0, False, {"chance": 0.0, "taller": [0.1, 0.2]}):
        assert config_from_dict({"env": {"obstacle_change": off}}).env.obstacle_change is None
    text = config_to_toml(Config())
    assert "obstacle_change" not in text
    meta = {"obs_mode": "conditioned", "layer_norm": True, "layers": [0, 128, 128, 0]}
    assert policy_config({**meta, "config_toml": text}, "p.npz").env.obstacle_change is None
    on = config_from_dict({"env": {"obstacle_change": 0.4}})
    assert on.env.obstacle_change == ChangeSpec(chance=0.4)
    text = config_to_toml(on)
    assert config_from_dict(tomllib.loads(text)) == on
    assert policy_config({**meta, "config_toml": text}, "p.npz") == on


# --------------------------------------------------------------------------------------------
# The change's geometry (NumPy, against independent computations)
# --------------------------------------------------------------------------------------------


def _draw(cfg, n=3000, seed=7):
    p = numpy_params(cfg)
    lay = scenarios.scenario_layouts(np, p, seed, n)
    u = scenarios.uniforms(np, np.full(n, 99, np.uint32), np.arange(n, dtype=np.uint32), 9)
    return p, lay, changes.changed_layout(np, p, lay, u), u


def _room(cfg, lay):
    near = lay.start_y + cfg.kinematics.foot_length + terrain.NEAR_MARGIN
    return near, lay.goal_y - terrain.FAR_MARGIN


def test_grown_obstacle_geometry():
    """Taller, wider and moved (the default ranges): the outline is the old one scaled about its
    centre, moved, and its box (from the vertices) is the layout's centre, width and height; the
    shape scales with the height; the height never passes the layout's tallest obstacle; the obstacle
    stays between the toe at the start and the goal (terrain's margins)."""
    cfg = _on({"chance": 1.0, "second": 0.0, "taller": [0.0, 1.0], "wider": [0.0, 1.0],
               "move": [-0.05, 0.05]})  # fmt: skip
    p, lay, c, u = _draw(cfg)
    assert np.all((c.at >= 5) & (c.at <= 14)) and len(np.unique(c.at)) == 10  # the default steps
    y, z = c.outline[..., 0], c.outline[..., 1]
    np.testing.assert_allclose(z.max(-1), c.height, rtol=1e-6)
    np.testing.assert_allclose(y.max(-1) - y.min(-1), c.width, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(0.5 * (y.max(-1) + y.min(-1)), c.center_y, atol=1e-6)
    ratio = c.height / lay.height
    np.testing.assert_allclose(c.shape, lay.shape * ratio[:, None], rtol=1e-5, atol=1e-7)
    tallest = cfg.layout.terrain.max_height
    assert np.all(ratio >= 1.0 - 1e-6) and np.all(c.height <= max(tallest, 0) + 1e-6)
    assert np.all(ratio <= 2.0 + 1e-6) and ratio.max() > 1.5
    near, far = _room(cfg, lay)
    old_left, old_right = lay.center_y - lay.width / 2, lay.center_y + lay.width / 2
    assert np.all(y.max(-1) <= np.maximum(far, old_right) + 1e-6)
    assert np.all(y.min(-1) >= np.minimum(near, old_left) - 1e-6)
    # the unit outline is unchanged: the new outline mapped back onto the old one
    unit_old = (lay.outline[..., 0] - lay.center_y[:, None]) / lay.width[:, None]
    unit_new = (y - c.center_y[:, None]) / c.width[:, None]
    np.testing.assert_allclose(unit_new, unit_old, atol=1e-5)
    moved = c.center_y - lay.center_y
    assert moved.min() < -0.04 and moved.max() > 0.04 and np.abs(moved).max() <= 0.05 + 1e-6


@pytest.mark.parametrize("table", ["terrain", "rectangles"])
def test_second_obstacle(table):
    """A second obstacle: on the default terrain (outlines of at most 8 of 16 vertices) a separate
    rectangle between the obstacle and the goal, the profile back on the floor between the two;
    on a layout of 4-vertex rectangles one rectangle covering both. The layout's box is the pair's,
    the shape the outline's heights (geometry.profile_height on the first's and the rectangle's
    outlines separately), and nothing reaches past the goal's margin."""
    layout = {} if table == "terrain" else {"terrain": False, "obstacles": ["base1", "base2"]}
    cfg = config_from_dict(
        {"env": {"obstacle_change": {"chance": 1.0, "second": 1.0}}, "layout": layout}
    )
    p, lay, c, u = _draw(cfg)
    ok = c.at >= 0
    # on terrain some scenes have no room ahead of the obstacle: no change there
    assert 0.3 < ok.mean() and (table == "rectangles" or ok.mean() < 1.0)
    near, far = _room(cfg, lay)
    y, z = c.outline[..., 0], c.outline[..., 1]
    old_left, old_right = lay.center_y - lay.width / 2, lay.center_y + lay.width / 2
    assert np.all(y.max(-1)[ok] <= far[ok] + 1e-6)
    np.testing.assert_allclose(y.min(-1), old_left, atol=1e-6)
    np.testing.assert_allclose(y.max(-1) - y.min(-1), c.width, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(z.max(-1), c.height, rtol=1e-6)
    w2 = y.max(-1) - old_right  # gap + second width
    assert np.all(w2[ok] >= changes.SECOND_MIN_WIDTH - 1e-6)
    if table == "rectangles":  # covered: one rectangle [left, right2] x [0, top]
        np.testing.assert_allclose(c.shape, np.broadcast_to(c.height[:, None], c.shape.shape))
        return
    # separate: the first's profile where it stands, a rectangle ahead of it, the floor between
    frac = geometry.descriptor_fractions(c.shape.shape[-1])
    ys = c.center_y[:, None] + c.width[:, None] * frac
    first = geometry.profile_height(np, ys, lay.outline[:, None])
    rect_y0 = y[:, -4]
    h2 = z[:, -3]
    second = np.where((ys >= rect_y0[:, None]) & (ys <= y[:, -1:]), h2[:, None], 0.0)
    # (0.1 mm: the first point lies 1e-6 of the width inside a steep near edge, float32 positions)
    np.testing.assert_allclose(c.shape[ok], np.maximum(first, second)[ok], atol=1e-4)
    assert np.all(h2 <= lay.height + 1e-6) and np.all(h2 >= 0.5 * lay.height - 1e-6)
    gap = rect_y0 - old_right
    mid = old_right + 0.5 * gap
    wide = ok & (gap > 0.005)
    assert wide.sum() > 100
    np.testing.assert_array_equal(
        geometry.profile_height(np, mid[:, None], c.outline[:, None])[wide, 0], 0.0
    )


# --------------------------------------------------------------------------------------------
# The environment (JAX)
# --------------------------------------------------------------------------------------------

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.env import ExoStepEnv  # noqa: E402

N = 512
STEPS = 14


def _rollout(env, state, params):
    """STEPS scripted moves from every state (up and forward at first, then forward and down), the
    states after each (a leading STEPS axis) and the rewards."""
    step = jax.vmap(env.step_env, in_axes=(None, 0, 0, None))
    moves = jnp.asarray([9, 9, 6, 9, 4, 6, 2, 4, 0, 2, 0, 34, 0, 32], jnp.int32)

    def body(s, a):
        obs, s2, r, term, _ = step(jax.random.PRNGKey(0), s, jnp.full(N, a), params)
        return s2, (s2, obs, r, term)

    return jax.lax.scan(body, state, moves)[1]


@pytest.fixture(scope="module")
def both_envs(default_config):
    import dataclasses

    on = dataclasses.replace(
        default_config, env=dataclasses.replace(default_config.env, shield=False)
    )
    off = on
    on = dataclasses.replace(
        on, env=dataclasses.replace(on.env, obstacle_change=_on().env.obstacle_change)
    )
    return ExoStepEnv(off), ExoStepEnv(on)


@pytest.fixture(scope="module")
def rollouts(both_envs):
    off, on = both_envs
    keys = jax.random.split(jax.random.PRNGKey(3), N)
    out = {}
    for name, env in (("off", off), ("on", on)):
        p = env.default_params
        obs, s0 = jax.vmap(env.reset, in_axes=(0, None))(keys, p)
        out[name] = (obs, s0, jax.jit(lambda s, env=env, p=p: _rollout(env, s, p))(s0))
    return out


def test_off_leaves_the_environment_as_it_was(both_envs, rollouts):
    """Off: no change in the state (no leaves); on: the same scenes from the same keys (the change's
    numbers come after the scene's), and until a change fires the same steps (heels and observations
    bit for bit); a layout started without a change steps as the environment without the option."""
    obs_off, s_off, (traj_off, o_off, r_off, t_off) = rollouts["off"]
    obs_on, s_on, (traj_on, o_on, r_on, t_on) = rollouts["on"]
    assert s_off.change is None and traj_off.change is None
    assert s_on.change is not None
    np.testing.assert_array_equal(np.asarray(obs_off), np.asarray(obs_on))
    for a, b in zip(jax.tree.leaves(s_off.layout), jax.tree.leaves(s_on.layout), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    at = np.asarray(s_on.change.at)
    t = np.arange(1, STEPS + 1)[:, None]
    before = t < np.where(at < 0, STEPS + 1, at)[None, :]  # (STEPS, N): the steps before the change
    assert before.mean() > 0.3
    np.testing.assert_array_equal(np.asarray(o_off)[before], np.asarray(o_on)[before])
    # Rewards to float32 rounding: the two programs differ (the change's selects), and XLA fuses
    # the reward's sums differently in each.
    np.testing.assert_allclose(
        np.asarray(r_off)[before], np.asarray(r_on)[before], rtol=1e-5, atol=2e-6
    )
    np.testing.assert_array_equal(
        np.asarray(traj_off.heel)[before], np.asarray(traj_on.heel)[before]
    )
    # An episode started on a layout with no change steps as the environment without the option.
    lay = jax.tree.map(lambda x: x[:N], s_off.layout)
    _, s_fixed = jax.vmap(both_envs[1].init_state, in_axes=(0, None))(
        lay, both_envs[1].default_params
    )
    assert np.all(np.asarray(s_fixed.change.at) == -1)
    fixed = jax.jit(lambda s: _rollout(both_envs[1], s, both_envs[1].default_params))(s_fixed)
    np.testing.assert_array_equal(np.asarray(fixed[1]), np.asarray(o_off))
    np.testing.assert_allclose(np.asarray(fixed[2]), np.asarray(r_off), rtol=1e-5, atol=2e-6)
    with pytest.raises(
        ValueError, match="change: this environment's config has env.obstacle_change off"
    ):
        both_envs[0].init_state(
            jax.tree.map(lambda x: x[0], lay), both_envs[0].default_params, s_on.change
        )


def test_layout_changes_exactly_at_the_drawn_step_never_onto_the_foot(both_envs, rollouts):
    """On: the layout is the drawn scene's before step ``at`` and, from ``at`` on, the changed one if
    the foot there keeps max(min_clearance, shield_clearance) from it (NumPy's exact foot clearance
    in float64, not the environment's), else the drawn one to the end; the observation shows the
    layout the state holds."""
    env = both_envs[1]
    p = env.default_params
    _, s0, (traj, obs, _, _) = rollouts["on"]
    at = np.asarray(s0.change.at)
    old = np.asarray(s0.layout.outline)
    new = np.asarray(s0.change.layout.outline)
    outl = np.asarray(traj.layout.outline)  # (STEPS, N, K, 2)
    heel = np.asarray(traj.heel, np.float64)
    need = max(float(p.min_clearance), float(p.shield_clearance))
    fired = skipped = 0
    for i in range(N):
        is_old = [np.array_equal(outl[t, i], old[i]) for t in range(STEPS)]
        is_new = [np.array_equal(outl[t, i], new[i]) for t in range(STEPS)]
        if at[i] < 0 or at[i] > STEPS:
            assert all(is_old)
            continue
        k = at[i] - 1  # the state after step ``at``
        assert all(is_old[:k])
        clear = float(
            geometry.foot_clearance(np, heel[k, i], float(p.foot_length), new[i].astype(np.float64))
        )
        if is_new[k]:
            fired += 1
            assert all(is_new[k:]) and clear >= need - 1e-6, (i, clear)
        else:
            skipped += 1
            assert all(is_old) and clear < need + 1e-6, (i, clear)
    assert fired > 100 and skipped > 10, (fired, skipped)
    # the observation after the switch is that of the new layout
    state_k = jax.tree.map(lambda x: x[STEPS - 1], traj)
    np.testing.assert_array_equal(
        np.asarray(obs[STEPS - 1]), np.asarray(jax.vmap(env.get_obs, in_axes=(0, None))(state_k, p))
    )
    # JAX's reset draws the change NumPy's changed_layout gives for the same numbers
    keys = jax.random.split(jax.random.PRNGKey(3), N)
    words = np.asarray(
        jax.random.key_data(keys) if jnp.issubdtype(keys.dtype, jax.dtypes.prng_key) else keys
    )
    n = scenarios.n_uniforms(p)
    u = scenarios.uniforms(np, words[:, 0], words[:, 1], n + changes.N_UNIFORMS)
    ref = changes.changed_layout(np, numpy_params(env.config), s0.layout, u[:, n:])
    np.testing.assert_array_equal(ref.at, at)
    np.testing.assert_allclose(ref.outline, new, atol=1e-6)


def test_training_with_obstacle_change_runs():
    """The compiled trainer with the option on: a few updates, finite, every state leaf vmapped."""
    from jaxexo.train.trainer import Hyperparams, Trainer

    raw = tiny_raw()
    raw["env"]["obstacle_change"] = 1.0
    cfg = config_from_dict(raw)
    trainer = Trainer(cfg)
    hyper = Hyperparams.from_config(cfg)
    ts = jax.jit(trainer.init)(jax.random.PRNGKey(0), hyper)
    assert ts.env_state.change.at.shape == (TINY_N,)
    ts, m = jax.jit(trainer.run, static_argnums=2)(ts, hyper, 2)
    assert int(trainer.env_steps(ts)) == 2 * TINY_N * TINY_T
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(ts.params))


def test_a_checkpoint_from_before_the_change_field_fits_a_state_without_changes():
    """A state dict with env_state.change None (obstacle changes off) is matched by a checkpoint
    that has the field as None, and by one written before the field existed (the key missing);
    a checkpoint whose field holds something where this config has nothing is refused."""
    from jaxexo.train.checkpoints import tree_mismatch, with_empty_fields

    template = {"env_state": {"heel": np.zeros(3), "change": None}, "step": np.zeros((), np.int32)}
    saved = {"env_state": {"heel": np.ones(3), "change": None}, "step": np.ones((), np.int32)}
    assert tree_mismatch(template, saved) is None
    old = {"env_state": {"heel": np.ones(3)}, "step": np.ones((), np.int32)}
    assert "keys differ" in tree_mismatch(template, old)
    filled = with_empty_fields(template, old)
    assert tree_mismatch(template, filled) is None and filled["env_state"]["change"] is None
    other = {
        "env_state": {"heel": np.ones(3), "change": {"at": np.ones(())}},
        "step": saved["step"],
    }
    assert "expected nothing, found dict" in tree_mismatch(template, other)
