"""The shield: the admissible moves of jaxexo.shield.rule.admissible_moves checked
against a dense brute-force look at each move (independent of jaxexo.physics.swept), the same mask in
JAX and NumPy, exploration and greedy choice inside the mask in the trainer and the generator, and
shielded raw paths that never fall back and keep the clearance."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.config import config_from_dict, load_config, numpy_params, scalar_params
from jaxexo.physics import actions, geometry, kinematics, terrain, transition  # noqa: F401
from jaxexo.physics.scene import stack_scenes
from jaxexo.shield import make_shield, rule

from conftest import ROOT, legacy_raw

SHIELD = 0.025


def _config(**env):
    raw = {
        "env": {"shield": True, "shield_clearance": SHIELD, **env},
        "layout": {"terrain": {"start_shift": [0.0, 0.12], "step_length": [0.55, 0.85]}},
    }
    return config_from_dict(legacy_raw(raw))


def _states(cfg, n, seed):
    """n terrain scenes (jaxexo.physics.scenarios, NumPy) and heel positions around their obstacles;
    every fifth heel low (0-3 cm), every tenth in the goal box's column, where the floor rule decides."""
    from jaxexo.physics import scenarios

    p = numpy_params(cfg)
    lay = scenarios.scenario_layouts(np, p, seed, n, False)
    rng = np.random.default_rng(seed)
    hy = (lay.center_y + rng.uniform(-0.4, 0.15, n)).astype(np.float32)
    hz = rng.uniform(0.0, 0.45, n).astype(np.float32)
    hz[::5] = rng.uniform(0.0, 0.03, len(hz[::5]))
    hy[::10] = (lay.goal_y[::10] + rng.uniform(-0.07, 0.03, len(hy[::10]))).astype(np.float32)
    return p, lay, hy, hz


def _dense_clearance(p, h0, h1, outline, n=600):
    """Min foot clearance over n + 1 positions along the move (geometry.foot_clearance, no swept code):
    at most |h1 - h0| / n above the exact clearance of the move."""
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    heels = h0 + t * (h1 - h0)
    return float(
        geometry.foot_clearance(
            np, heels, float(p.foot_length), outline[None].astype(np.float64)
        ).min()
    )


# Off: the shield before the floor rule (legacy_raw); on: the default's goal on the floor and its rule.
FLOOR_RULE = {"off": {}, "on": {"floor_clearance": 0.02, "goal_tolerance": [0.04, 0.005]}}


@pytest.mark.parametrize("floor", sorted(FLOOR_RULE))
def test_admissible_moves_against_dense_sampling(floor):
    cfg = _config(**FLOOR_RULE[floor])
    p, lay, hy, hz = _states(cfg, 300, 3)

    m = rule.admissible_moves(np, p, hy, hz, lay)
    for kind in ("rows", "scalar"):  # the NumPy forms (all three: tests/test_shield_forms.py)
        form = make_shield(kind, p, scalar_params(cfg))
        np.testing.assert_array_equal(form.admissible(hy, hz, lay), m)
    d = p.directions.astype(np.float64)
    step = float(p.step_size)
    blocked_near = fallback = checked = floor_blocked = 0
    for i in range(len(hy)):
        h0 = np.array([hy[i], hz[i]], np.float64)
        c_here = float(
            geometry.foot_clearance(np, h0, float(p.foot_length), lay.outline[i].astype(np.float64))
        )
        if c_here <= 1e-4:
            continue  # a heel inside or on the obstacle: not a state a shielded agent reaches
        need = min(SHIELD, c_here)
        dense, reach, before_goal, off_floor = [], [], [], []
        for a in range(actions.NUM_ACTIONS):
            y, z = transition.move_heel(np, p, hy[i], hz[i], d[a, 0], d[a, 1])
            h1 = np.array([y, z], np.float64)
            dense.append(_dense_clearance(p, h0, h1, lay.outline[i]))
            reach.append(
                not bool(
                    kinematics.swing_heel_unreachable(
                        np,
                        float(lay.pivot_y[i]),
                        h1,
                        float(p.thigh),
                        float(p.shin),
                        p.hip_limits,
                        p.knee_limits,
                    )
                )
            )
            # the floor rule by hand: low only in the goal box's column (a band of 1e-6 m left to rounding)
            column = abs(h1[0] - float(lay.goal_y[i])) <= float(p.goal_tolerance[0]) - 1e-6
            before_goal.append(
                h1[0] <= float(lay.goal_y[i]) + float(p.goal_tolerance[0])
                and (h1[1] >= float(p.floor_clearance) + 1e-6 or column)
            )
            off_floor.append(
                h1[1] >= float(p.floor_clearance) - 1e-6
                or abs(h1[0] - float(lay.goal_y[i])) <= float(p.goal_tolerance[0]) + 1e-6
            )
        dense, reach, before_goal = np.array(dense), np.array(reach), np.array(before_goal)
        off_floor = np.array(off_floor)
        forward = d[:, 0] >= 0.0
        assert m[i].any(), "some move is always offered"
        assert not (m[i] & ~forward).any(), "a backward move was admitted"
        # Where a move passes every condition by the independent look (with a rounding margin either
        # way), the mask is exactly the moves that pass them all.
        sure_ok = forward & reach & before_goal & (dense >= need + step / 600 + 1e-5)
        if not sure_ok.any():
            fallback += 1
            continue
        checked += 1
        admitted = m[i]
        assert (dense[admitted] >= need - 1e-5).all(), (i, dense[admitted], need)
        assert (reach[admitted] & off_floor[admitted]).all(), i
        refused = forward & reach & before_goal & ~admitted
        assert (dense[refused] < need + step / 600 + 1e-5).all(), (i, dense[refused], need)
        blocked_near += int(refused.sum())
        floor_blocked += int((forward & reach & ~off_floor).sum())
    assert blocked_near > 50, "the scenes must exercise the clearance condition"
    assert checked > 120, (checked, fallback)  # enough states with a move passing every condition
    if floor == "on":
        assert floor_blocked > 100, "the scenes must exercise the floor rule"


def test_shield_off_admits_every_move():
    cfg = config_from_dict(legacy_raw({"env": {"shield": False}}))
    p, lay, hy, hz = _states(cfg, 20, 1)

    assert rule.admissible_moves(np, p, hy, hz, lay).all()


def test_vertical_move_up_is_admissible_from_any_safe_pose():
    """Terrain is closed downward, so lifting the foot never brings it closer: a shielded agent is
    never cornered below the ceiling."""
    cfg = _config()
    p, lay, hy, hz = _states(cfg, 400, 5)

    m = rule.admissible_moves(np, p, hy, hz, lay)
    up = int(np.argmin(np.abs(actions.action_angles() - np.pi / 2)))
    c = geometry.foot_clearance(
        np,
        np.stack([hy, hz], -1).astype(np.float64),
        float(p.foot_length),
        lay.outline.astype(np.float64),
    )
    kin_ok = ~kinematics.swing_heel_unreachable(
        np,
        lay.pivot_y,
        np.stack([hy, hz + float(p.step_size)], -1),
        float(p.thigh),
        float(p.shin),
        p.hip_limits,
        p.knee_limits,
    )
    free = (c > 0) & (hz + float(p.step_size) < float(p.max_z_world)) & kin_ok
    assert free.sum() > 100
    assert m[free, up].all()


@pytest.mark.slow
def test_jax_mask_equals_numpy_and_exploration_stays_inside():
    import jax
    import jax.numpy as jnp

    from jaxexo.env import ExoStepEnv
    from jaxexo.train.trainer import Hyperparams, Trainer

    cfg = _config()
    env = ExoStepEnv(cfg)
    p = env.default_params
    obs, st = jax.vmap(env.reset, in_axes=(0, None))(
        jax.random.split(jax.random.PRNGKey(0), 512), p
    )
    rng = np.random.default_rng(0)
    heel = np.stack(
        [np.asarray(st.layout.center_y) + rng.uniform(-0.35, 0.1, 512), rng.uniform(0, 0.4, 512)],
        -1,
    ).astype(np.float32)
    st = st.replace(heel=jnp.asarray(heel))
    m_jax = np.asarray(jax.jit(jax.vmap(env.action_mask, in_axes=(0, None)))(st, p))
    import types

    lay = types.SimpleNamespace(
        **{k: np.asarray(v) for k, v in vars(st.layout).items() if not k.startswith("_")}
        if hasattr(st.layout, "__dict__")
        else {}
    )
    lay = types.SimpleNamespace(
        outline=np.asarray(st.layout.outline),
        pivot_y=np.asarray(st.layout.pivot_y),
        goal_y=np.asarray(st.layout.goal_y),
    )
    m_np = rule.admissible_moves(np, numpy_params(cfg), heel[:, 0], heel[:, 1], lay)
    assert (
        m_jax == m_np
    ).mean() > 0.999  # float32 fused arithmetic may flip a move on the boundary
    assert (~m_jax).sum() > 512 * 17  # the backward moves, and some more

    trainer = Trainer(cfg)
    hyper = Hyperparams.from_config(cfg)
    params = trainer.net.init(jax.random.PRNGKey(1), obs[:1])
    mask = jnp.asarray(m_jax)
    for eps in (1.0, 0.0):
        a, _ = jax.jit(trainer._act)(params, obs, jax.random.PRNGKey(2), eps, mask)
        assert np.asarray(mask)[np.arange(512), np.asarray(a)].all()
    del hyper


def test_shielded_generator_never_falls_back_and_keeps_clearance(tmp_path):
    """A shielded policy (here random weights: the shield alone must guarantee this) never moves the
    heel backward and keeps the shield's clearance over every raw move, by the dense look."""
    from jaxexo.inference.scenarios import safety_scenarios

    from test_clearance_option import _random_generator

    cfg = _config()
    gen = _random_generator(cfg)
    sc = safety_scenarios(cfg, 60, seed=11)
    n_checked = 0
    for s in sc:
        scene = gen.scene(s.obstacle, pivot=s.pivot, start_y=s.start_y, step_length=s.step_length)
        raw, acts = gen.rollout(scene)
        assert np.all(np.diff(raw[:, 0]) >= -1e-6)
        c0 = float(
            geometry.foot_clearance(np, raw[0], float(cfg.kinematics.foot_length), scene.outline)
        )
        for k in range(len(raw) - 1):
            dense = _dense_clearance(gen.np_params, raw[k], raw[k + 1], scene.outline)
            assert dense >= min(SHIELD, c0) - 1e-5
            n_checked += 1
        raws_b, acts_b = gen.rollout_batch([scene])
        np.testing.assert_array_equal(acts_b[0], acts)
    assert n_checked > 500


def test_pruned_numpy_clearance_rule_decides_like_the_exact_one():
    """NumPy's moves_keep_clearance skips the exact swept distance where the ends' clearances decide;
    the generic path (any other array module: here NumPy behind a namespace) computes every move."""
    import types

    cfg = _config()
    p, lay, hy, hz = _states(cfg, 3000, 9)
    ends = rule.forward_ends(np, p, hy, hz)
    pruned = rule.moves_keep_clearance(np, p, hy, hz, ends, lay.outline)
    generic = types.SimpleNamespace(**{k: getattr(np, k) for k in dir(np) if not k.startswith("_")})
    exact = rule.moves_keep_clearance(generic, p, hy, hz, ends, lay.outline)
    np.testing.assert_array_equal(pruned, exact)
    assert 0.05 < (~exact).mean() < 0.95  # both outcomes exercised
    # one heel at a time (the generator's single rollout) takes the unpruned path: the same decisions
    for i in range(0, 3000, 150):
        one = rule.moves_keep_clearance(np, p, hy[i], hz[i], ends[i], lay.outline[i])
        np.testing.assert_array_equal(one, exact[i])


@pytest.mark.parametrize(
    "env, field",
    [
        ({"shield": "yes"}, "env.shield"),
        ({"shield": 1}, "env.shield"),
        ({"shield_clearance": -0.01}, "env.shield_clearance"),
        ({"shield_clearance": float("nan")}, "env.shield_clearance"),
    ],
)
def test_bad_shield_settings_are_refused_naming_the_field(env, field):
    from jaxexo.config import ConfigError

    with pytest.raises(ConfigError, match=rf"^{field}"):
        config_from_dict(legacy_raw({"env": env}))


@pytest.mark.slow
def test_batched_jax_mask_decides_exactly_like_the_plain_one():
    """The trainer's batched mask (jaxexo.shield.batched: bounds decide most moves, the exact swept check
    the rest, gathered into a buffer) equals ``action_mask`` (the plain rule, every move checked) bit
    for bit, on thousands of states: heels around the obstacles of the training distribution
    (configs/default.toml's terrain), the states a shielded random policy visits there, and heels
    around the held-out terrain families; with the default buffer and with one small enough that
    a step takes many rounds."""
    import jax
    import jax.numpy as jnp

    from jaxexo.env import ExoStepEnv
    from jaxexo.physics.scenarios import unseen_scenarios
    from jaxexo.shield import batched

    cfg = load_config(ROOT / "configs" / "default.toml")
    env = ExoStepEnv(cfg)
    p = env.default_params
    plain = jax.jit(jax.vmap(env.action_mask, in_axes=(0, None)))
    fast = jax.jit(env.action_masks)
    small = jax.jit(
        lambda st: make_shield("jax", p, buffer=64).admissible(
            st.heel[:, 0], st.heel[:, 1], st.layout, last_action=st.last_action
        )
    )
    rng = np.random.default_rng(24)

    def around(st, n):
        heel = np.stack(
            [
                np.asarray(st.layout.center_y) + rng.uniform(-0.4, 0.15, n),
                rng.uniform(0.0, 0.45, n),
            ],
            -1,
        )
        return st.replace(heel=jnp.asarray(heel, jnp.float32))

    n = 2048
    _, st = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(7), n), p)
    batches = [around(st, n)]

    def visit(st, key):  # a shielded random policy: the states training sees early on
        k1, k2 = jax.random.split(key)
        a = jax.random.categorical(k1, jnp.where(env.action_masks(st, p), 0.0, -jnp.inf))
        _, st, *_ = jax.vmap(env.step, in_axes=(0, 0, 0, None))(jax.random.split(k2, n), st, a, p)
        return st, st

    _, seen = jax.jit(
        lambda st: jax.lax.scan(visit, st, jax.random.split(jax.random.PRNGKey(8), 24))
    )(st)
    batches += [jax.tree.map(lambda x, t=t: x[t], seen) for t in range(0, 24, 3)]
    scenes = unseen_scenarios(cfg.kinematics.foot_length, repeats=4)
    held = [env.layout_for(s.obstacle, s.pivot, s.start_y, s.step_length) for s in scenes]
    lay = jax.tree.map(lambda *x: jnp.stack(x), *held)
    st_held = jax.tree.map(lambda x: x[: len(held)], st).replace(layout=lay)
    batches += [around(st_held, len(held)) for _ in range(4)]

    pairs = decided = 0
    for b in batches:
        ref = np.asarray(plain(b, p))
        np.testing.assert_array_equal(np.asarray(fast(b, p)), ref)
        np.testing.assert_array_equal(np.asarray(small(b)), ref)
        heel, out = b.heel, b.layout.outline
        ends = rule.forward_ends(jnp, p, heel[:, 0], heel[:, 1])
        c = geometry.foot_clearance(jnp, heel, p.foot_length, out)
        sp, sf = batched.bounds(p, heel[:, 0], heel[:, 1], ends, out, c)
        pairs += sp.size
        decided += int(np.sum(np.asarray(sp | sf)))
    assert sum(len(b.heel) for b in batches) > 20000
    # the bounds decide most moves, and leave some to the exact check
    assert 0.5 < decided / pairs < 0.99, decided / pairs


def test_shield_never_undoes_the_last_move_nor_stands_still():
    """The shield's fifth condition: a move the ground cancels (down from the ground) and the move that
    undoes the last one (down right after up, up right after down) are not admissible; in the JAX
    environment the state carries the last move, and a fresh episode has none."""
    import jax
    import jax.numpy as jnp

    from jaxexo.env import ExoStepEnv

    cfg = _config()
    env = ExoStepEnv(cfg)
    p = env.default_params
    up, down = 9, 27
    assert np.allclose(
        actions.action_directions()[[up, down]], [[0.0, 1.0], [0.0, -1.0]], atol=1e-12
    )
    obs, st = env.reset(jax.random.PRNGKey(3), p)
    assert int(st.last_action) == -1
    free = st.replace(
        heel=jnp.asarray([float(st.layout.start_y), 0.10], jnp.float32)
    )  # far before the obstacle
    mask = jax.jit(env.action_mask)
    m = np.asarray(mask(free, p))
    assert m[up] and m[down]
    assert not np.asarray(mask(free.replace(last_action=jnp.asarray(up, jnp.int32)), p))[down]
    assert not np.asarray(mask(free.replace(last_action=jnp.asarray(down, jnp.int32)), p))[up]
    assert np.asarray(mask(free.replace(last_action=jnp.asarray(0, jnp.int32)), p))[
        [up, down]
    ].all()
    assert not np.asarray(mask(st, p))[down]  # on the ground: down would not move the heel
    _, st2, *_ = env.step_env(jax.random.PRNGKey(0), free, jnp.asarray(up), p)
    assert int(st2.last_action) == up and not np.asarray(mask(st2, p))[down]
    assert np.array_equal(
        np.asarray(env.action_masks(jax.tree.map(lambda x: x[None], st2), p))[0],
        np.asarray(mask(st2, p)),
    )


@pytest.mark.slow
def test_shielded_swings_visit_no_point_twice():
    """With the fifth condition a shielded swing's heel never falls back in y and never reverses at one
    y, so no point is visited twice, except at steps where no move passes every condition (the mask's
    fall-backs). Checked on the raw paths of a shielded random-weight policy (which would otherwise
    dither freely) over the training distribution and the held-out families, against the conditions
    recomputed at each step with the plain clearance rule."""
    from test_fast_shield import _random_generator, _scenes

    gen = _random_generator(seed=7)
    p = gen.np_params
    _, scenes = _scenes(gen, 200, 200)
    paths, acts = gen.rollout_batch(scenes)
    fallbacks = steps = 0
    for scene, path, act in zip(scenes, paths, acts):
        lay = stack_scenes([scene], np.float32)
        pts = path.astype(np.float32)
        for k in range(1, len(act)):
            steps += 1
            hy, hz = pts[k, :1], pts[k, 1:2]
            ends = rule.forward_ends(np, p, hy, hz)
            clear = rule.moves_keep_clearance(np, p, hy, hz, ends, lay.outline)
            tier = rule.shield_conditions(
                np, p, hy, hz, lay, rule.FORWARD, ends, clear, act[k - 1 : k]
            )
            if not tier.any():
                fallbacks += 1
                continue
            assert pts[k + 1, 0] >= pts[k, 0], "the heel fell back"
            assert not np.array_equal(pts[k + 1], pts[k]), "a move that did not move the heel"
            assert not np.array_equal(pts[k + 1], pts[k - 1]), "the last move undone"
    assert steps - fallbacks > 5000


def test_greedy_rollouts_with_the_batched_mask_equal_the_plain_mask_bit_for_bit():
    """Validation and evaluation roll a batch of layouts out greedily with the batched mask
    (jaxexo.train.evaluate.make_rollouts): every output, heel paths included, equals the same rollouts
    with the plain rule (``vmap(action_mask)``, every move checked exactly), for a shielded policy on
    the default model's validation scenes; one layout's rollout (``make_rollout``) is its row."""
    import jax
    import jax.numpy as jnp

    from jaxexo.env import ExoStepEnv
    from jaxexo.train.evaluate import make_rollout, make_rollouts, validation_set
    from jaxexo.train.network import QNetwork

    cfg = load_config(ROOT / "configs" / "default.toml")
    env, params, layouts = validation_set(cfg, n=96)
    net = QNetwork(hidden=(32, 32), layer_norm=True)
    q = net.init(jax.random.PRNGKey(3), jnp.zeros((1, env.obs_dim)))
    fast = jax.jit(make_rollouts(env, net.apply, cfg.env.max_steps, record=True))(
        q, layouts, params
    )
    plain_env = ExoStepEnv(cfg)
    plain_env.action_masks = lambda st, p=None: jax.vmap(plain_env.action_mask, in_axes=(0, None))(
        st, p
    )
    plain = jax.jit(make_rollouts(plain_env, net.apply, cfg.env.max_steps, record=True))(
        q, layouts, params
    )
    for a, b in zip(jax.tree.leaves(fast), jax.tree.leaves(plain), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert fast[1].shape == (96, cfg.env.max_steps, 2)
    # random weights: some episodes end early, some run to the limit, so both paths are exercised
    steps = np.asarray(fast[0].steps)
    assert steps.min() < cfg.env.max_steps and (steps == cfg.env.max_steps).any(), np.unique(steps)
    one = jax.jit(make_rollout(env, net.apply, cfg.env.max_steps, record=True))(
        q, jax.tree.map(lambda x: x[5], layouts), params
    )
    for a, b in zip(
        jax.tree.leaves(one), jax.tree.leaves(jax.tree.map(lambda x: x[5], fast)), strict=True
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
