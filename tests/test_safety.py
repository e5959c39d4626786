"""The safe-swing definition: the exact swept clearance of jaxexo.physics.swept against dense
brute force, a verdict that no denser sampling of the same curve contradicts, the environment's moves
that cannot jump through a corner, the margin in the config, and the generator's CFFTG fallback."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from jaxexo.config import ConfigError, config_from_dict, numpy_params, scalar_params
from jaxexo.inference import Obstacle, TrajectoryGenerator
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import geometry, outcome, swept, transition
from jaxexo.physics.scene import make_scene, stack_scenes
from jaxexo.shield.rows import take_rows
from jaxexo.swing import smoothing as sm
from jaxexo.swing.trajectory import assemble

from conftest import legacy_raw

FOOT = 0.2


# --------------------------------------------------------------------------------------------
# Brute-force references (independent of jaxexo.physics.swept)
# --------------------------------------------------------------------------------------------


def _seg_points(a, b, n):
    t = np.linspace(0.0, 1.0, n)[:, None]
    return a + t * (b - a)


def brute_swept(h0, h1, outline, n_move=81, n_foot=81, n_edge=81):
    """Distance between many foot positions along the move (many points along each foot) and many
    points along each outline edge; 0 when a foot point is inside the obstacle. Returns the
    distance, the sampling resolution (an upper bound on brute - exact) and the distance to the
    outline's edges alone (inside or not)."""
    heels = _seg_points(h0, h1, n_move)
    s = np.linspace(0.0, FOOT, n_foot)
    pts = (heels[:, None, :] + np.stack([s, 0 * s], -1)[None]).reshape(-1, 2)
    edge_pts = np.concatenate(
        [_seg_points(outline[i], outline[i + 1], n_edge) for i in range(len(outline) - 1)]
    )
    d = np.sqrt(((pts[:, None, :] - edge_pts[None]) ** 2).sum(-1)).min()
    inside = geometry.point_in_obstacle(np, pts, outline).any()
    edge_len = np.max(np.linalg.norm(np.diff(outline, axis=0), axis=1))
    res = 0.5 * (
        np.linalg.norm(h1 - h0) / (n_move - 1) + FOOT / (n_foot - 1) + edge_len / (n_edge - 1)
    )
    return (0.0 if inside else d), res, d


@st.composite
def outlines(draw):
    """Convex (rectangle, triangle, half-ellipse) and non-convex (random profile) outlines."""
    kind = draw(st.sampled_from(["rectangle", "triangle", "half_ellipse", "profile"]))
    c = draw(st.floats(0.35, 0.55))
    w, h = draw(st.floats(0.02, 0.25)), draw(st.floats(0.02, 0.25))
    if kind != "profile":
        return getattr(Obstacle, kind)(w, h, center_y=c).outline
    k = draw(st.integers(2, 8))
    z = draw(st.lists(st.floats(0.0, 0.25), min_size=k, max_size=k))
    y = np.linspace(c - w / 2, c + w / 2, k)
    return Obstacle.profile(
        np.column_stack([y, z]) if max(z) > 0 else [[c - w / 2, h], [c + w / 2, h]]
    ).outline


@settings(max_examples=80)
@given(
    outline=outlines(),
    h0=st.tuples(st.floats(-0.1, 0.8), st.floats(0.0, 0.35)),
    move=st.tuples(st.floats(-0.15, 0.15), st.floats(-0.15, 0.15)),
)
def test_swept_distance_is_exact_against_dense_brute_force(outline, h0, move):
    h0 = np.array(h0)
    h1 = h0 + np.array(move)
    exact = float(swept.swept_distance(np, h0, h1, FOOT, outline))
    brute, res, boundary = brute_swept(h0, h1, outline)
    if brute == 0.0 and boundary > res:
        # The whole move inside the obstacle, clear of its boundary: swept_distance is the distance to
        # the boundary (module docstring), and the signed clearance the checks use says inside.
        assert float(swept.swept_clearance(np, h0, h1, FOOT, outline)) <= 0.0
        brute = boundary
    # The brute force looks at a subset of the swept region and of the outline: never below the exact
    # distance, and within its sampling resolution above it.
    assert exact <= brute + 1e-12
    assert brute - exact <= res + 1e-9
    # the term-by-term form the shield and the environment use under XLA: the same terms, the same value
    assert (
        float(swept.swept_distance_by_edge(np, h0, h1, FOOT, outline[:, 0], outline[:, 1])) == exact
    )


def test_swept_distance_under_jit_matches_numpy():
    import jax
    import jax.numpy as jnp

    rng = np.random.default_rng(0)
    outline = Obstacle.profile([[0.35, 0.1], [0.42, 0.02], [0.5, 0.18], [0.55, 0.05]]).outline
    h0 = rng.uniform([0.0, 0.0], [0.7, 0.3], (500, 2))
    h1 = h0 + rng.uniform(-0.1, 0.1, (500, 2))
    ref = swept.swept_clearance(np, h0, h1, FOOT, outline[None])
    f = jax.jit(lambda a, b, o: swept.swept_clearance(jnp, a, b, FOOT, o))
    got = np.asarray(
        f(
            jnp.asarray(h0, jnp.float32),
            jnp.asarray(h1, jnp.float32),
            jnp.asarray(outline[None], jnp.float32),
        )
    )
    np.testing.assert_allclose(got, ref, atol=2e-5)
    assert (ref <= 0).any() and (ref > 0.02).any()  # both contact and clear moves were tried


def test_a_two_sample_line_through_the_triangle_fails():
    cfg = config_from_dict(legacy_raw())
    sp = scalar_params(cfg)
    scene = make_scene(Obstacle.named("triangle"), "between", foot_length=FOOT)
    line = np.array([[[0.0, 0.0], [0.70, 0.0]]])
    # Both samples are 15 cm clear of the triangle; the move between them goes through it.
    assert geometry.foot_clearance(np, line[0], FOOT, scene.outline).min() > 0.1
    b = assemble("test", sp, [scene], [line[0]], line, [0.0], deviation=[0.0])
    assert not b.ok[0] and not b.collision_free[0] and b.min_clearance[0] <= 0.0
    assert any("touches the obstacle" in r for r in b.reasons[0])


@settings(max_examples=60)
@given(
    outline=outlines(),
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(2, 12),
    smoothing=st.sampled_from([0.0, 0.001, 0.005]),
)
# a 2-sample move along the ground through a rectangle's base (swept distance 7e-18 m, not 0)
@example(
    outline=np.array([[0.25, 0.0], [0.25, 0.25], [0.5, 0.25], [0.5, 0.0]]),
    seed=90981,
    n=2,
    smoothing=0.0,
)
def test_a_verdict_at_n_samples_holds_at_10n(outline, seed, n, smoothing):
    """Every path the verdict calls clear at N samples is clear at 10 N samples of the same curve (the
    per-sample exact foot distance of jaxexo.physics.geometry, not the swept one), and the guaranteed
    clearance is never above what the denser look finds."""
    rng = np.random.default_rng(seed)
    m = int(rng.integers(2, 25))
    raw = np.column_stack([np.linspace(0.0, 0.7, m), np.abs(rng.normal(0.2, 0.12, m))])
    raw[0, 1] = raw[-1, 1] = 0.0
    if smoothing > 0:
        coarse, dev = sm.smooth_paths([raw], n, smoothing, with_deviation=True)
        fine = sm.smooth_paths([raw], 10 * (n - 1) + 1, smoothing)[0]
        coarse, dev = coarse[0], dev[0]
    else:
        coarse, dev = sm.linear_resample(raw, n, with_deviation=True)
        fine = sm.linear_resample(raw, 10 * (n - 1) + 1)
        # The polyline itself, densely: the raw corners that coarse samples skip are checked too.
        fine = np.concatenate([fine, raw])
    guaranteed = swept.path_swept_clearance(np, coarse, FOOT, outline).min() - dev
    dense = geometry.foot_clearance(np, fine, FOOT, outline).min()
    # The swept distance is 0 for a move that crosses the outline between two clear samples (it is a
    # distance, signed only through the samples' own clearance), so against a denser look that finds
    # the foot inside, the guarantee is compared where that look finds it clear or touching.
    assert guaranteed <= max(dense, 0.0) + 1e-9
    if dense <= 0.0:
        # contact is never hidden between samples: the verdict's contact rule (geometry.foot_collides,
        # within TOUCH_EPS) holds; a foot sliding along the obstacle's base line computes a swept
        # distance of ~1e-17 m, not exactly 0 (hypothesis found it)
        assert geometry.foot_collides(np, guaranteed)
    if guaranteed >= 0.02:
        assert dense >= 0.02


# --------------------------------------------------------------------------------------------
# Environment, reward and config
# --------------------------------------------------------------------------------------------


def _step(xp, cfg, prev, heel, max_y=None):
    p = numpy_params(cfg)
    scene = make_scene(Obstacle.named("base1"), "obstacle", foot_length=FOOT)  # [0.35, 0.55] x 0.10
    lay = stack_scenes([scene], np.float32)
    lay = take_rows(lay, 0)
    if xp is not np:
        from jaxexo.env.params import EnvParams

        p = EnvParams.from_config(cfg)
        lay = lay._replace(**{k: xp.asarray(v) for k, v in lay._asdict().items() if v is not None})
    # the move from prev to heel as one step along (heel - prev) / step_size
    d = xp.asarray((np.asarray(heel) - prev) / float(np.asarray(p.step_size)), xp.float32)
    prev = xp.asarray(prev, xp.float32)
    out = transition.step(
        xp,
        p,
        prev[0],
        prev[1],
        d,
        xp.asarray(0),
        xp.asarray(False),
        lay,
        max_steps=cfg.env.max_steps,
        max_y=max_y,
    )
    info = {
        k: np.asarray(getattr(out.info, k))
        for k in ("collision", "clearance", "backward", "traj_terms")
    }
    # What the one verdict (jaxexo.physics.outcome) makes of this move: its margin and backward checks.
    v = outcome.verdict(
        np, True, info["clearance"], True, True, info["backward"], **outcome.rule(cfg.env)
    )
    info["backward_violation"] = not v.backward_ok
    info["unsafe"] = not (v.clearance_ok and v.backward_ok)
    return info


@pytest.mark.parametrize("xp_name", ["numpy", "jax"])
def test_an_env_move_cannot_jump_through_a_corner(xp_name):
    import importlib

    xp = np if xp_name == "numpy" else importlib.import_module("jax.numpy")
    cfg = config_from_dict(legacy_raw())
    # The toe goes from 1 cm left of base1's near wall (below its top) to 1.5 cm above its top: both
    # ends are clear, the chord passes 5 mm under the corner (0.35, 0.10).
    prev, heel = np.array([0.34 - FOOT, 0.085]), np.array([0.37 - FOOT, 0.115])
    for h in (prev, heel):
        assert geometry.foot_clearance(np, h, FOOT, Obstacle.named("base1").outline) > 0.009
    info = _step(xp, cfg, prev, heel)
    assert info["collision"] and info["unsafe"] and info["clearance"] <= 0.0
    # A move that stays 1.5 cm above the top: no contact, but closer than the 2 cm margin: unsafe, and
    # the safety term (eq 2.35, safety_distance >= margin) is paid.
    info = _step(xp, cfg, np.array([0.30, 0.115]), np.array([0.33, 0.115]))
    assert not info["collision"] and info["unsafe"] and abs(info["clearance"] - 0.015) < 1e-5
    assert info["traj_terms"][6] < 0
    # 3 cm above: safe. The heel 6 mm behind its largest y so far: unsafe (backward tolerance 5 mm).
    info = _step(xp, cfg, np.array([0.30, 0.13]), np.array([0.33, 0.13]))
    assert not info["unsafe"]
    info = _step(xp, cfg, np.array([0.0, 0.13]), np.array([0.0, 0.16]), max_y=np.float32(0.006))
    assert info["unsafe"] and info["backward_violation"]
    info = _step(xp, cfg, np.array([0.0, 0.13]), np.array([0.0, 0.16]), max_y=np.float32(0.004))
    assert not info["unsafe"]


def test_the_margin_is_validated_at_config_load():
    raw = {"env": {"min_clearance": 0.04}, "reward": {"safety_distance": 0.03}}
    with pytest.raises(ConfigError, match="reward.safety_distance"):
        config_from_dict(legacy_raw(raw))
    with pytest.raises(ConfigError, match="env.min_clearance"):
        config_from_dict(legacy_raw({"env": {"min_clearance": -0.01}}))
    with pytest.raises(ConfigError, match="env.backward_tolerance"):
        config_from_dict(legacy_raw({"env": {"backward_tolerance": float("nan")}}))
    cfg = config_from_dict(legacy_raw({"env": {"min_clearance": 0.03}}))
    assert cfg.env.min_clearance == 0.03 and cfg.env.backward_tolerance == 0.005


# --------------------------------------------------------------------------------------------
# The generator: no false "safe", and the CFFTG fallback
# --------------------------------------------------------------------------------------------


def _dense_recheck(gen, t, factor=10):
    """Clearance and backward motion of trajectory t's own curve at factor x denser sampling."""
    n = len(t.heel)
    dense_n = factor * (n - 1) + 1
    if any("jaxexo.swing.clearing" in note for note in t.notes):
        # the corrected spline (jaxexo.swing.clearing), its own coefficients at the dense parameters
        from jaxexo.swing.clearing import clear_smooth

        out = clear_smooth(
            t.raw,
            t.scene.outline,
            gen.sp.foot_length,
            gen.sp.min_clearance,
            n,
            t.smoothing,
            dense_points=dense_n,
        )
        np.testing.assert_allclose(out[0], t.heel, rtol=0, atol=1e-9)  # the same curve
        fine = out[3]
        y = fine[:, 0]
    elif np.isnan(t.smoothing):
        fine = np.concatenate([sm.linear_resample(t.raw, dense_n), t.raw])
        y = sm.linear_resample(t.raw, dense_n)[:, 0]
    else:
        fine = (
            sm.smooth_paths([t.raw], dense_n, t.smoothing)[0]
            if t.smoothing > 0
            else sm.linear_resample(t.raw, dense_n)
        )
        y = fine[:, 0]
    c = geometry.foot_clearance(np, fine, gen.sp.foot_length, t.scene.outline).min()
    return c, float(np.max(np.maximum.accumulate(y) - y))


@pytest.mark.parametrize("unseen", [False, True])
def test_no_rl_trajectory_flagged_safe_fails_at_10x_density(trained_run, unseen):
    gen = TrajectoryGenerator.load(trained_run / "policy.npz")
    sc = safety_scenarios(gen.config, 150, unseen=unseen)
    b = gen.generate_batch(
        [s.obstacle for s in sc],
        pivot=[s.pivot for s in sc],
        start_y=[s.start_y for s in sc],
        step_length=[s.step_length for s in sc],
        fallback=None,
    )
    margin, tol = gen.config.env.min_clearance, gen.config.env.backward_tolerance
    for i in np.flatnonzero(b.ok):
        c, back = _dense_recheck(gen, b[i])
        assert c >= margin, (i, c)
        assert back <= tol
        assert b.min_clearance[i] <= c + 1e-9


def test_cfftg_fallback_replaces_an_unsafe_rl_swing(trained_run):
    gen = TrajectoryGenerator.load(trained_run / "policy.npz")
    ob = Obstacle.named("triangle")
    # Two samples (below generate's MIN_POINTS, so through finish): the RL swing is the straight line
    # from start to goal, through the triangle; CFFTG's polynomial at two samples is that line too:
    # neither is safe, and the result says so.
    scene = gen.scene(ob, pivot="between")
    line = np.array([[scene.start_y, 0.0], [scene.goal_y, 0.0]])
    t2 = gen.finish([scene], [line], 2, 0.0, 1.0, "cfftg")[0]
    assert not t2.ok and any("CFFTG fallback failed too" in n for n in t2.notes)
    rl2 = gen.finish([scene], [line], 2, 0.0, 1.0, None)[0]
    assert not rl2.ok and rl2.method == "rl" and not rl2.checks.collision_free
    # An RL swing that skims the triangle's apex (1 cm above it) is replaced by CFFTG's plan.
    raw = np.array([[0.0, 0.0], [0.05, 0.1], [0.25, 0.21], [0.45, 0.21], [0.65, 0.1], [0.70, 0.0]])
    rl = gen.finish([scene], [raw], 100, 0.0, 1.0, None)[0]
    assert not rl.ok and rl.checks.collision_free and not rl.checks.clearance_ok
    t = gen.finish([scene], [raw], 100, 0.0, 1.0, "cfftg")[0]
    assert (
        t.method == "cfftg-fallback"
        and t.ok
        and t.checks.min_clearance >= gen.config.env.min_clearance
    )
    assert any(n.startswith("RL swing failed the safe-swing check") for n in t.notes)
    # The batch falls back row by row; a safe RL row stays RL.
    high = np.array(
        [[0.0, 0.0], [0.05, 0.15], [0.25, 0.30], [0.45, 0.30], [0.65, 0.15], [0.70, 0.0]]
    )
    b = gen.finish([scene, scene], [raw, high], 100, 0.0, 1.0, "cfftg")
    assert b[1].ok, b.reasons[1]
    assert [b[i].method for i in range(2)] == ["cfftg-fallback", "rl"] and b.ok.all()
    np.testing.assert_array_equal(b[0].heel, t.heel)
    with pytest.raises(ValueError, match="fallback"):
        gen.generate(ob, fallback="polynomial")
    assert gen.generate_batch([ob], fallback="none")[0].method == "rl"
