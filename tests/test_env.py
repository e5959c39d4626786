"""jaxexo.env.ExoStepEnv: jit/vmap over every obstacle kind, auto-reset, determinism, params vmap,
a scripted policy that reaches the goal, and the gymnax 1.0 contract through gymnax's wrappers."""

from __future__ import annotations

import chex
import numpy as np
import pytest

jax = pytest.importorskip("jax")
jnp = pytest.importorskip("jax.numpy")

from jaxexo.config import config_from_dict  # noqa: E402
from jaxexo.env import NUM_ACTIONS, ExoStepEnv  # noqa: E402
from jaxexo.physics import geometry  # noqa: E402
from jaxexo.physics.geometry import Obstacle  # noqa: E402
from jaxexo.physics.kinematics import PIVOT_CONDITIONS  # noqa: E402

from conftest import MIXED_KINDS, MIXED_RAW, get_mixed_env, get_mixed_step, legacy_raw  # noqa: E402

BATCH = 512
ROLLOUT = 110  # > max_steps = 100: every episode that does not reach the goal is truncated
RIGHT, UP, DOWN = 0, 9, 27


def _mixed_env(**env_overrides):
    raw = {**MIXED_RAW, "env": {**MIXED_RAW["env"], **env_overrides}}
    return ExoStepEnv(config_from_dict(legacy_raw(raw)))


# --------------------------------------------------------------------------------------------
# chex variants: the same single-env transitions with and without jit
# --------------------------------------------------------------------------------------------


def _env():
    return get_mixed_env()


class EnvVariantsTest(chex.TestCase):
    @chex.variants(with_jit=True, without_jit=True)
    def test_reset_and_step(self):
        env = _env()
        params = env.default_params
        reset = self.variant(env.reset)
        step = self.variant(env.step)
        obs, state = reset(jax.random.PRNGKey(3), params)
        chex.assert_shape(obs, (env.obs_dim,))
        chex.assert_tree_all_finite(obs)
        chex.assert_shape(state.heel, (2,))
        chex.assert_shape(state.layout.outline, (env.max_vertices, 2))
        chex.assert_shape(state.layout.shape, (env.shape_points,))
        assert int(state.time) == 0 and not bool(state.visited_mid)
        np.testing.assert_allclose(np.asarray(state.heel), [float(state.layout.start_y), 0.0])
        out = step(jax.random.PRNGKey(4), state, UP, params)
        obs2, state2, reward, terminated, truncated, info = out
        chex.assert_shape(obs2, (env.obs_dim,))
        chex.assert_rank([reward, terminated, truncated], 0)
        chex.assert_type([terminated, truncated], bool)
        chex.assert_shape(info["traj_terms"], (8,))
        chex.assert_shape(info["exo_terms"], (4,))
        chex.assert_shape(info["joint_angles"], (4,))
        chex.assert_tree_all_finite((obs2, reward, info["traj_terms"], info["exo_terms"]))
        np.testing.assert_allclose(
            np.asarray(state2.heel), np.asarray(state.heel) + [0.0, 0.03], atol=1e-6
        )
        assert int(state2.time) == 1
        # Jitted and eager agree (float32 rounding only).
        ref = get_mixed_step()(jax.random.PRNGKey(4), state, UP, params)
        chex.assert_trees_all_close(out, ref, atol=1e-5)


# --------------------------------------------------------------------------------------------
# A jitted, vmapped rollout over a batch mixing every kind and pivot condition
# --------------------------------------------------------------------------------------------


def _make_rollout(env, n_steps):
    @jax.jit
    def rollout(key, params):
        k_reset, k_run = jax.random.split(key)
        obs, state = jax.vmap(env.reset, in_axes=(0, None))(
            jax.random.split(k_reset, BATCH), params
        )

        def body(carry, k):
            obs, state = carry
            k_act, k_step = jax.random.split(k)
            action = jax.random.randint(k_act, (BATCH,), 0, NUM_ACTIONS)
            obs2, state2, reward, terminated, truncated, info = jax.vmap(
                env.step, in_axes=(0, 0, 0, None)
            )(jax.random.split(k_step, BATCH), state, action, params)
            out = dict(
                obs=obs2,
                reward=reward,
                terminated=terminated,
                truncated=truncated,
                prev_time=state.time,
                time=state2.time,
                heel=state2.heel,
                kind=state2.layout.kind,
                pivot_kind=state2.layout.pivot_kind,
                center_y=state2.layout.center_y,
                traj=info["traj_terms"],
                exo=info["exo_terms"],
                final_obs=info["final_observation"],
                shaping=info.get("shaping", jnp.zeros_like(reward)),
                goal=info["goal_reached"],
            )
            return (obs2, state2), out

        (_, _), traj = jax.lax.scan(body, (obs, state), jax.random.split(k_run, n_steps))
        return obs, state, traj

    return rollout


@pytest.fixture(scope="module")
def mixed(mixed_env):
    params = mixed_env.default_params
    rollout = _make_rollout(mixed_env, ROLLOUT)
    obs0, state0, traj = rollout(jax.random.PRNGKey(0), params)
    traj = jax.tree.map(np.asarray, traj)
    return dict(env=mixed_env, params=params, rollout=rollout, obs0=obs0, state0=state0, traj=traj)


def test_batch_shapes_and_finite(mixed):
    env, t = mixed["env"], mixed["traj"]
    chex.assert_shape(mixed["obs0"], (BATCH, env.obs_dim))
    assert env.obs_dim == 14 + env.shape_points
    chex.assert_shape(t["obs"], (ROLLOUT, BATCH, env.obs_dim))
    chex.assert_shape([t["reward"], t["terminated"], t["truncated"], t["time"]], (ROLLOUT, BATCH))
    chex.assert_shape(t["traj"], (ROLLOUT, BATCH, 8))
    chex.assert_shape(t["exo"], (ROLLOUT, BATCH, 4))
    assert t["terminated"].dtype == np.bool_ and t["truncated"].dtype == np.bool_
    assert np.isfinite(t["obs"]).all() and np.isfinite(mixed["obs0"]).all()
    assert np.isfinite(t["reward"]).all()
    assert np.isfinite(t["traj"]).all() and np.isfinite(t["exo"]).all()
    # The heel stays in bounds: above the ground, below the ceiling.
    assert (t["heel"][..., 1] >= 0).all() and (
        t["heel"][..., 1] <= mixed["env"].config.env.max_z + 1e-6
    ).all()


def test_every_kind_and_pivot_appears(mixed):
    st = mixed["state0"]
    kinds = np.asarray(st.layout.kind)
    pivots = np.asarray(st.layout.pivot_kind)
    assert set(kinds.tolist()) == set(range(len(MIXED_KINDS)))
    assert set(pivots.tolist()) == set(range(len(PIVOT_CONDITIONS)))


def test_sampled_layouts_respect_the_config(mixed):
    env, st = mixed["env"], mixed["state0"]
    lay = jax.tree.map(np.asarray, st.layout)
    cfg = env.config
    specs = cfg.layout.obstacles
    for i, spec in enumerate(specs):
        sel = lay.kind == i
        assert sel.any()
        assert (lay.width[sel] >= spec.width[0] - 1e-6).all() and (
            lay.width[sel] <= spec.width[1] + 1e-6
        ).all()
        assert (lay.height[sel] >= spec.height[0] - 1e-6).all() and (
            lay.height[sel] <= spec.height[1] + 1e-6
        ).all()
        # The outline is the kind's unit outline scaled and placed; its shape descriptor scales with height.
        unit = geometry.pad_outline(spec.unit_vertices(), env.max_vertices)
        j = np.flatnonzero(sel)[0]
        np.testing.assert_allclose(
            lay.outline[j, :, 0], lay.center_y[j] + lay.width[j] * unit[:, 0], atol=1e-5
        )
        np.testing.assert_allclose(lay.outline[j, :, 1], lay.height[j] * unit[:, 1], atol=1e-5)
        np.testing.assert_allclose(
            lay.shape[j],
            lay.height[j] * geometry.shape_descriptor(unit, env.shape_points),
            atol=1e-5,
        )
    step_len = lay.goal_y - lay.start_y
    assert (step_len >= 0.65 - 1e-5).all() and (step_len <= 0.75 + 1e-5).all()
    assert (lay.start_y >= -1e-7).all() and (lay.start_y <= 0.05 + 1e-6).all()
    center0 = 0.5 * (cfg.kinematics.foot_length + step_len)
    assert (np.abs(lay.center_y - center0) <= 0.03 + 1e-5).all()
    for k, name in enumerate(PIVOT_CONDITIONS):
        sel = lay.pivot_kind == k
        expected = {
            "agent": lay.start_y,
            "obstacle": lay.center_y,
            "between": 0.5 * (lay.start_y + lay.center_y),
        }[name]
        np.testing.assert_allclose(lay.pivot_y[sel], expected[sel], atol=1e-6)
    # The heel starts on the ground at the start; the toe is clear of the obstacle.
    np.testing.assert_allclose(
        np.asarray(st.heel), np.stack([lay.start_y, 0 * lay.start_y], -1), atol=1e-7
    )
    assert (lay.center_y - 0.5 * lay.width > lay.start_y + cfg.kinematics.foot_length).all()
    assert (lay.center_y + 0.5 * lay.width < lay.goal_y).all()


def test_auto_reset_and_flags(mixed):
    t = mixed["traj"]
    max_steps = mixed["env"].config.env.max_steps
    term, trunc = t["terminated"], t["truncated"]
    done = term | trunc
    # Both flags only where the goal is reached on the step that hits the limit (gymnax 1.0.1).
    assert not (term & trunc & ~(t["goal"] & (t["prev_time"] + 1 == max_steps))).any()
    assert trunc.any(), "110 random steps must truncate some episodes"
    # Truncation exactly at the step limit; after any finished episode the new state's time is 0.
    assert (t["prev_time"][trunc] + 1 == max_steps).all()
    assert (t["time"][done] == 0).all()
    assert (t["time"][~done] == t["prev_time"][~done] + 1).all()
    # Every episode still running at step 100 of the rollout was truncated there (none survive).
    assert (t["time"] < max_steps).all()
    # Terminated only by the goal (penalty collision mode).
    assert (t["goal"][term]).all()
    # final_observation is the next observation unless the episode ended.
    np.testing.assert_array_equal(t["final_obs"][~done], t["obs"][~done])
    # A new layout after a reset (the centre is drawn anew, differs almost surely).
    prev_center = np.concatenate(
        [np.asarray(mixed["state0"].layout.center_y)[None], t["center_y"][:-1]]
    )
    assert (t["center_y"][done] != prev_center[done]).mean() > 0.99
    assert (t["center_y"][~done] == prev_center[~done]).all()


def test_reward_is_weighted_sum_of_terms(mixed):
    t, p = mixed["traj"], mixed["params"]
    expected = (
        t["traj"] @ np.asarray(p.traj_weights) + t["exo"] @ np.asarray(p.exo_weights) + t["shaping"]
    )
    np.testing.assert_allclose(t["reward"], expected, atol=1e-4)
    # Penalties are non-positive; only r0 and the goal term may be positive.
    assert (
        (t["traj"][..., 1:3] <= 0).all()
        and (t["traj"][..., 4:] <= 0).all()
        and (t["exo"] <= 0).all()
    )
    assert (t["traj"][..., 3] >= 0).all()


def test_determinism(mixed):
    rollout, params = mixed["rollout"], mixed["params"]
    obs0, state0, traj = rollout(jax.random.PRNGKey(0), params)
    for key, value in mixed["traj"].items():
        np.testing.assert_array_equal(np.asarray(traj[key]), value, err_msg=key)
    np.testing.assert_array_equal(np.asarray(obs0), np.asarray(mixed["obs0"]))
    _, state_b, traj_b = rollout(jax.random.PRNGKey(1), params)
    assert not np.array_equal(
        np.asarray(state_b.layout.center_y), np.asarray(state0.layout.center_y)
    )
    assert not np.array_equal(np.asarray(traj_b["heel"]), mixed["traj"]["heel"])


def test_single_reset_determinism(mixed):
    env, params = mixed["env"], mixed["params"]
    reset = env.reset  # eager
    o1, s1 = reset(jax.random.PRNGKey(42), params)
    o2, s2 = reset(jax.random.PRNGKey(42), params)
    o3, s3 = reset(jax.random.PRNGKey(43), params)
    chex.assert_trees_all_equal((o1, s1), (o2, s2))
    assert float(s1.layout.center_y) != float(s3.layout.center_y)


# --------------------------------------------------------------------------------------------
# Observations, params vmap, collision termination
# --------------------------------------------------------------------------------------------


def test_thesis_obs_mode():
    from jaxexo.env.exo_step import LENGTH_SCALE, THESIS_OBS_CENTER

    env = _mixed_env(obs_mode="thesis")
    assert env.obs_dim == 2
    params = env.default_params
    # Eager (op-by-op): cheaper than compiling this env's transitions once more.
    obs, state = env.reset(jax.random.PRNGKey(0), params)
    chex.assert_shape(obs, (2,))
    np.testing.assert_allclose(
        np.asarray(obs), (np.asarray(state.heel) - THESIS_OBS_CENTER) / LENGTH_SCALE, atol=1e-6
    )
    obs2, state2, *_ = env.step(jax.random.PRNGKey(1), state, UP, params)
    chex.assert_shape(obs2, (2,))
    np.testing.assert_allclose(
        np.asarray(obs2) - np.asarray(obs), [0.0, 0.03 / LENGTH_SCALE], atol=1e-6
    )
    assert env.observation_space(params).shape == (2,)


def test_conditioned_obs_content(mixed):
    from jaxexo.env.exo_step import LENGTH_SCALE

    env = mixed["env"]
    obs = np.asarray(mixed["obs0"])
    lay = jax.tree.map(np.asarray, mixed["state0"].layout)
    # heel - start = 0 and heel z = 0 at reset; goal relative to the heel; progress 0, not visited.
    np.testing.assert_allclose(obs[:, 2], 0.0, atol=1e-6)
    np.testing.assert_allclose(obs[:, 3], 0.0, atol=1e-6)
    np.testing.assert_allclose(obs[:, 4], (lay.goal_y - lay.start_y) / LENGTH_SCALE, atol=1e-5)
    np.testing.assert_allclose(obs[:, -2:], 0.0)
    # The obstacle's profile: its true shape descriptor, or (if the package observes only the bounding
    # box, ``obs_true_profile`` false) its height at every point.
    true_profile = bool(getattr(mixed["params"], "obs_true_profile", True))
    profile = lay.shape if true_profile else np.broadcast_to(lay.height[:, None], lay.shape.shape)
    np.testing.assert_allclose(
        obs[:, 12 : 12 + env.shape_points], profile / LENGTH_SCALE, atol=1e-5
    )
    # Obstacle near edge, far edge and top relative to the heel (on the ground at the start).
    np.testing.assert_allclose(
        obs[:, 9], (lay.center_y - 0.5 * lay.width - lay.start_y) / LENGTH_SCALE, atol=1e-5
    )
    np.testing.assert_allclose(
        obs[:, 10], (lay.center_y + 0.5 * lay.width - lay.start_y) / LENGTH_SCALE, atol=1e-5
    )
    np.testing.assert_allclose(obs[:, 11], lay.height / LENGTH_SCALE, atol=1e-5)
    np.testing.assert_allclose(obs[:, 8], (lay.pivot_y - lay.start_y) / LENGTH_SCALE, atol=1e-5)


def test_params_vmap_over_step_size(mixed_env):
    env = mixed_env
    p = env.default_params
    p2 = p.replace(step_size=jnp.asarray(0.02, jnp.float32))
    stacked = jax.tree.map(lambda a, b: jnp.stack([a, b]), p, p2)
    chex.assert_shape(stacked.step_size, (2,))
    chex.assert_shape(stacked.directions, (2, NUM_ACTIONS, 2))

    @jax.jit
    def go(params):
        def one(pp):
            obs, state = env.reset(jax.random.PRNGKey(0), pp)
            obs, state, reward, *_ = env.step(jax.random.PRNGKey(1), state, RIGHT, pp)
            return state.heel - jnp.stack([state.layout.start_y, 0.0]), reward

        return jax.vmap(one)(params)

    moved, reward = go(stacked)
    np.testing.assert_allclose(np.asarray(moved), [[0.03, 0.0], [0.02, 0.0]], atol=1e-6)
    chex.assert_shape(reward, (2,))


def test_collision_terminates_when_configured(mixed_env, mixed_step):
    env, jit_step = mixed_env, mixed_step
    params = env.default_params
    lay = env.layout_for(Obstacle.named("base1"), pivot="agent")
    _, state = env.init_state(lay, params)
    state = state.replace(heel=jnp.asarray([0.30, 0.05], jnp.float32))
    # Penalty mode (the thesis): collide and continue.
    _, st_pen, _, term, trunc, info = jit_step(jax.random.PRNGKey(0), state, RIGHT, params)
    assert bool(info["collision"]) and not bool(term) and not bool(trunc)
    assert int(st_pen.time) == 1
    # Terminate mode: the same step ends the episode and resets.
    p_term = params.replace(terminate_on_collision=jnp.asarray(True))
    _, st_term, _, term, trunc, info = jit_step(jax.random.PRNGKey(0), state, RIGHT, p_term)
    assert bool(term) and not bool(trunc) and not bool(info["goal_reached"])
    assert int(st_term.time) == 0
    np.testing.assert_allclose(
        np.asarray(info["final_observation"]),
        np.asarray(
            env.get_obs(
                state.replace(
                    heel=jnp.asarray([0.33, 0.05], jnp.float32), time=jnp.asarray(1, jnp.int32)
                ),
                params,
            )
        ),
        atol=1e-6,
    )


@pytest.mark.parametrize(
    "heel, expect_term, expect_trunc",
    [
        # the 100th step reaches the goal: terminated and, as in gymnax 1.0.1 (truncation from the step
        # count alone, gymnax.environments.environment.Environment.step), truncated too
        ([0.66, 0.0], True, True),
        ([0.10, 0.0], False, True),  # the 100th step anywhere else: truncated
    ],
)
def test_last_step_flags(mixed_env, mixed_step, heel, expect_term, expect_trunc):
    env = mixed_env
    params = env.default_params
    _, state = env.init_state(env.layout_for(Obstacle.named("base2"), pivot="between"), params)
    state = state.replace(heel=jnp.asarray(heel, jnp.float32), time=jnp.asarray(99, jnp.int32))
    obs, new_state, reward, term, trunc, info = mixed_step(
        jax.random.PRNGKey(7), state, RIGHT, params
    )
    assert (bool(term), bool(trunc)) == (expect_term, expect_trunc)
    assert bool(info["terminated"]) == expect_term and bool(info["truncated"]) == expect_trunc
    # Either way the episode is over: a fresh one starts (time 0, heel on the ground at its start).
    assert int(new_state.time) == 0 and not bool(new_state.visited_mid)
    np.testing.assert_allclose(
        np.asarray(new_state.heel), [float(new_state.layout.start_y), 0.0], atol=1e-7
    )
    from jaxexo.env.exo_step import LENGTH_SCALE, THESIS_OBS_CENTER

    np.testing.assert_allclose(
        np.asarray(info["final_observation"])[:2],
        (np.asarray(heel) + [0.03, 0.0] - np.asarray(THESIS_OBS_CENTER)) / LENGTH_SCALE,
        atol=1e-5,
    )
    assert not np.allclose(np.asarray(obs), np.asarray(info["final_observation"]))


def test_terminate_mode_from_config():
    env = _mixed_env(collision="terminate")
    assert bool(env.default_params.terminate_on_collision)
    assert not bool(_env().default_params.terminate_on_collision)


def test_layout_for_errors(mixed_env):
    with pytest.raises(ValueError, match="pivot"):
        mixed_env.layout_for(Obstacle.named("base1"), pivot="left")
    with pytest.raises(ValueError, match="obstacle"):
        mixed_env.layout_for(Obstacle.named("base1", center_y=0.25))  # reaches back to the toe
    with pytest.raises(ValueError, match="step_length"):
        mixed_env.layout_for(Obstacle.named("base1"), step_length=0.5)  # goal before its far edge
    with pytest.raises(ValueError, match="step_length"):
        mixed_env.layout_for(Obstacle.named("base1"), step_length=float("nan"))


# --------------------------------------------------------------------------------------------
# A scripted policy: up, across, down reaches the goal
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["base1", "base2", "base3", "triangle", "half_circle"])
@pytest.mark.parametrize("pivot", PIVOT_CONDITIONS)
def test_scripted_policy_reaches_goal(mixed_env, mixed_step, kind, pivot):
    env = mixed_env
    params = env.default_params
    ob = Obstacle.named(kind)
    lay = env.layout_for(ob, pivot=pivot, step_length=0.70)
    _, state = env.init_state(lay, params)
    n_up = int(np.ceil((ob.height + 0.05) / 0.03))  # 5 cm over the top
    n_across = 23  # 0.69 m: inside the goal's 4 cm
    actions = [UP] * n_up + [RIGHT] * n_across + [DOWN] * n_up
    key = jax.random.PRNGKey(0)
    total = 0.0
    for i, a in enumerate(actions):
        key, k = jax.random.split(key)
        obs, new_state, reward, term, trunc, info = mixed_step(k, state, a, params)
        assert not bool(info["collision"]), (kind, pivot, i)
        assert not bool(trunc)
        total += float(reward)
        if i < len(actions) - 1:
            assert not bool(term), (kind, pivot, i)
            state = new_state
    assert bool(term) and bool(info["goal_reached"])
    assert float(info["traj_terms"][3]) > 0
    np.testing.assert_allclose(np.asarray(info["heel"]), [0.69, 0.0], atol=1e-5)
    # Auto-reset after the goal: a fresh episode.
    assert int(new_state.time) == 0
    assert np.isfinite(total)


# --------------------------------------------------------------------------------------------
# gymnax itself: spaces and wrappers
# --------------------------------------------------------------------------------------------


def test_gymnax_spaces(mixed_env):
    from gymnax.environments import spaces as gspaces

    env = mixed_env
    params = env.default_params
    a_space = env.action_space(params)
    o_space = env.observation_space(params)
    assert isinstance(a_space, gspaces.Discrete) and a_space.n == NUM_ACTIONS == env.num_actions
    assert isinstance(o_space, gspaces.Box) and tuple(o_space.shape) == (env.obs_dim,)
    acts = jax.vmap(a_space.sample)(jax.random.split(jax.random.PRNGKey(0), 1000))
    assert acts.min() >= 0 and acts.max() < NUM_ACTIONS and len(np.unique(np.asarray(acts))) > 30
    assert bool(jnp.all(jax.vmap(a_space.contains)(acts)))
    obs, _ = env.reset(jax.random.PRNGKey(0), params)
    assert bool(o_space.contains(obs))
    assert env.name == "ExoStep-v0"


def test_gymnax_observation_space_sample_is_finite(mixed_env):
    o_space = mixed_env.observation_space(mixed_env.default_params)
    x = o_space.sample(jax.random.PRNGKey(0))
    chex.assert_shape(x, (mixed_env.obs_dim,))
    assert bool(jnp.all(jnp.isfinite(x)))
    assert bool(o_space.contains(x))


def test_gymnax_wrappers_rollout(mixed_env):
    from gymnax.wrappers.purerl import FlattenObservationWrapper, LogWrapper

    env = LogWrapper(FlattenObservationWrapper(mixed_env))
    params = mixed_env.default_params
    n_envs, n_steps = 8, 105

    @jax.jit
    def run(key):
        k0, k1 = jax.random.split(key)
        obs, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k0, n_envs), params)
        a_space = env.action_space(params)

        def body(carry, k):
            obs, state = carry
            ka, ks = jax.random.split(k)
            action = jax.vmap(a_space.sample)(jax.random.split(ka, n_envs))
            obs, state, reward, terminated, truncated, info = jax.vmap(
                env.step, in_axes=(0, 0, 0, None)
            )(jax.random.split(ks, n_envs), state, action, params)
            return (obs, state), (
                obs,
                reward,
                terminated,
                truncated,
                info["returned_episode"],
                info["returned_episode_lengths"],
                info["returned_episode_returns"],
            )

        return jax.lax.scan(body, (obs, state), jax.random.split(k1, n_steps))

    (obs, state), (o, r, term, trunc, ret_ep, ret_len, ret_ret) = run(jax.random.PRNGKey(0))
    chex.assert_shape(o, (n_steps, n_envs, mixed_env.obs_dim))
    chex.assert_shape([r, term, trunc], (n_steps, n_envs))
    assert np.isfinite(np.asarray(o)).all() and np.isfinite(np.asarray(r)).all()
    done = np.asarray(term | trunc)
    np.testing.assert_array_equal(np.asarray(ret_ep), done)
    assert done.any()
    # An episode truncated by the step limit is 100 steps long.
    lens = np.asarray(ret_len)[np.asarray(trunc)]
    assert lens.size > 0 and (lens == mixed_env.config.env.max_steps).all()
    # The returned return of the first finished episode is the sum of its rewards.
    e = int(np.flatnonzero(done.any(axis=0))[0])
    t_end = int(np.flatnonzero(done[:, e])[0])
    np.testing.assert_allclose(
        float(ret_ret[t_end, e]), float(np.asarray(r)[: t_end + 1, e].sum()), rtol=1e-4, atol=1e-3
    )


@pytest.mark.parametrize("which", ["mixed", "terrain"])
def test_step_batch_equals_vmapped_step_bit_for_bit(mixed_env, which):
    """``step_batch`` (fresh scenes drawn only where an episode ended, jaxexo.shield.compact) against
    ``jax.vmap(step)`` (a scene drawn for every environment at every step): every output and every
    state leaf equal bit for bit over 110 random steps (episodes of staggered ages: some end at
    most steps, and at one step more than one round of the buffer's 16), on the mixed
    obstacles and on procedural terrain, and vmapped over two environment parameter sets."""
    from jaxexo.config import load_config

    from conftest import ROOT

    env = (
        mixed_env
        if which == "mixed"
        else ExoStepEnv(load_config(ROOT / "configs" / "default.toml"))
    )
    p = env.default_params
    params = jax.tree.map(
        lambda a, b: jnp.stack([a, b]), p, p.replace(step_size=jnp.asarray(0.04, jnp.float32))
    )
    n = 256

    def rollout(batched, pp):
        _, state = jax.vmap(env.reset, in_axes=(0, None))(
            jax.random.split(jax.random.PRNGKey(5), n), pp
        )
        # Episodes at staggered ages, so that some are truncated at most steps, and 40 at one step.
        age = jax.random.randint(jax.random.PRNGKey(7), (n,), 0, 100, jnp.int32)
        state = state.replace(time=age.at[:40].set(50))

        def body(state, k):
            ka, ks = jax.random.split(k)
            a = jax.random.randint(ka, (n,), 0, NUM_ACTIONS)
            keys = jax.random.split(ks, n)
            if batched:  # the reset keys that step splits off
                obs, st, s, final = env.step_batch(
                    jax.vmap(jax.random.split)(keys)[:, 1], state, a, pp
                )
                info = {**s.info._asdict(), "terminated": s.terminated, "truncated": s.truncated}
                out = (
                    obs,
                    st,
                    s.reward,
                    s.terminated,
                    s.truncated,
                    info | {"final_observation": final},
                )
            else:
                out = jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys, state, a, pp)
            return out[1], out

        return jax.lax.scan(body, state, jax.random.split(jax.random.PRNGKey(6), ROLLOUT))

    fast = jax.jit(jax.vmap(lambda pp: rollout(True, pp)))(params)
    ref = jax.jit(jax.vmap(lambda pp: rollout(False, pp)))(params)
    done = np.asarray(ref[1][3] | ref[1][4])
    assert (done.sum(-1) > 0).mean() > 0.8 and done.sum(
        -1
    ).max() > 16  # most steps end some; one takes rounds
    for a, b in zip(jax.tree.leaves(fast), jax.tree.leaves(ref), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
