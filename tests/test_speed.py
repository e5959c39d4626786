"""The generator's fast paths against the plain reference implementation: the swept
check's pruning bound against the exact swept clearance, the pruned per-path minimum against the
full one, and ``generate`` / ``generate_batch`` (fast) against ``plain_reference`` on thousands of scenes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxexo.physics import geometry, swept

from test_safety import FOOT, outlines


@settings(max_examples=300, deadline=None)
@given(
    outline=outlines(),
    h0=st.tuples(st.floats(-0.1, 0.8), st.floats(0.0, 0.35)),
    move=st.tuples(st.floats(-0.15, 0.15), st.floats(-0.15, 0.15)),
)
def test_swept_lower_bound_never_exceeds_the_exact_clearance(outline, h0, move):
    h0 = np.array(h0)
    h1 = h0 + np.array(move)
    c0 = float(geometry.foot_clearance(np, h0, FOOT, outline))
    c1 = float(geometry.foot_clearance(np, h1, FOOT, outline))
    exact = float(swept.swept_clearance(np, h0, h1, FOOT, outline))
    if min(c0, c1) > 0.0:
        assert float(swept.swept_lower_bound(np, c0, c1, np.linalg.norm(move))) <= exact + 1e-12
    assert exact <= min(c0, c1) + 1e-12


def _random_paths(rng, n_paths, n):
    """Heel paths that rise over the obstacle region and land, with noise (some through the obstacle)."""
    u = np.linspace(0.0, 1.0, n)
    for _ in range(n_paths):
        start, goal = rng.uniform(-0.1, 0.1), rng.uniform(0.6, 0.9)
        apex = rng.uniform(0.0, 0.35)
        y = start + (goal - start) * u + rng.normal(0, 0.01, n)
        z = np.maximum(
            apex * np.sin(np.pi * u) ** rng.uniform(0.5, 2.0) + rng.normal(0, 0.005, n), 0.0
        )
        yield np.column_stack([y, z])


def test_pruned_swept_minimum_matches_the_full_swept_clearance():
    rng = np.random.default_rng(0)
    kinds = [
        geometry.Obstacle.rectangle,
        geometry.Obstacle.triangle,
        geometry.Obstacle.half_ellipse,
    ]
    pruned_any = 0
    rects = []
    for i, path in enumerate(_random_paths(rng, 3000, int(rng.integers(5, 120)))):
        ob = kinds[i % 3](
            rng.uniform(0.02, 0.25), rng.uniform(0.02, 0.25), center_y=rng.uniform(0.35, 0.55)
        )
        c = geometry.foot_clearance(np, path, FOOT, ob.outline[None])
        full = swept.path_swept_clearance(np, path, FOOT, ob.outline, c)
        fast = swept.path_swept_min(path[None], FOOT, ob.outline[None], c[None])[0]
        assert fast.shape == full.shape
        assert fast.min() == full.min()
        assert np.argmin(fast) == np.argmin(full)
        assert np.all(fast <= full + 1e-12)  # elsewhere a lower bound ...
        assert np.all(fast[fast != full] > full.min())  # ... that stays above the minimum
        pruned_any += int(np.sum(fast != full))
        if i % 3 == 0:
            rects.append((path, ob.outline, c, full))
    assert pruned_any > 0
    # Many paths at once (one vectorised geometry call for all candidate moves): the same per path.
    path, outline, c, full = (np.stack(x) for x in zip(*rects))
    fast = swept.path_swept_min(path, FOOT, outline, c)
    assert np.array_equal(fast.min(axis=1), full.min(axis=1))
    assert np.array_equal(np.argmin(fast, axis=1), np.argmin(full, axis=1))


def _random_outline(rng, i):
    """A rectangle, a triangle, a half-ellipse or a random (non-convex) profile, by i."""
    c, w, h = rng.uniform(0.35, 0.55), rng.uniform(0.02, 0.25), rng.uniform(0.02, 0.25)
    if i % 4 < 3:
        kind = ("rectangle", "triangle", "half_ellipse")[i % 4]
        return getattr(geometry.Obstacle, kind)(w, h, center_y=c).outline
    y = np.linspace(c - w / 2, c + w / 2, int(rng.integers(2, 9)))
    return geometry.Obstacle.profile(np.column_stack([y, rng.uniform(0.01, 0.25, len(y))])).outline


def test_one_polylines_clearance_equals_the_exact_swept_clearance():
    """swept.polyline_clearances (the timed verdict's: distances to the foot's reach at a few heels,
    exact only on the stretches that can hold the closest move) against the exact clearance of every
    move and sample (swept.path_swept_clearance): the same minimum to rounding, at a move whose
    exact clearance is that minimum, lower bounds everywhere; and None (the caller then takes the
    exact functions) on every path that touches the obstacle, and only near it."""
    rng = np.random.default_rng(1)
    fast = touching = 0
    for i, path in enumerate(_random_paths(rng, 1200, int(rng.integers(100, 400)))):
        outline = _random_outline(rng, i)
        c = geometry.foot_clearance(np, path, FOOT, outline[None])
        full = swept.path_swept_clearance(np, path, FOOT, outline, c)
        got = swept.polyline_clearances(path, FOOT, outline)
        touching += int(full.min() <= 0.0)
        if got is None:
            # Not taken: the path comes within a stretch's length of the outline, or starts in
            # the outline's box.
            continue
        points, moves = got
        assert full.min() > 0.0
        assert moves.shape == full.shape and points.shape == c.shape
        assert abs(moves.min() - full.min()) <= 1e-15
        assert full[np.argmin(moves)] <= full.min() + 1e-15
        assert np.all(moves <= full + 1e-15) and np.all(points <= c + 1e-15)
        fast += 1
    assert touching > 500 and fast > 0.8 * (1200 - touching)  # taken on most that keep off
    # Below the floor, or not moving: not taken.
    path = np.column_stack([np.linspace(0.0, 0.8, 50), np.full(50, 0.3)])
    assert swept.polyline_clearances(path, FOOT, _random_outline(rng, 0)) is not None
    path[10, 1] = -1e-9
    assert swept.polyline_clearances(path, FOOT, _random_outline(rng, 0)) is None
    assert swept.polyline_clearances(np.zeros((5, 2)), FOOT, _random_outline(rng, 0)) is None


def _same(a, b):
    """Two trajectories agree: samples to 1e-9 m, every check and reason, the method used."""
    assert a.method == b.method
    np.testing.assert_allclose(a.heel, b.heel, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.joint_angles, b.joint_angles, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(a.raw, b.raw)
    # The verdict exactly; the clearance figures to float rounding (the fast path may smooth the
    # retried rows together, in one matrix product, where the reference smooths them one by one).
    ca, cb = a.checks, b.checks
    for f in (
        "reached_goal",
        "collision_free",
        "joint_limits_ok",
        "leg_length_ok",
        "clearance_ok",
        "above_ground",
    ):
        assert getattr(ca, f) == getattr(cb, f), f
    assert ca.ok == cb.ok and len(ca.reasons) == len(cb.reasons)
    for f in ("min_clearance", "heel_backward", "deviation"):
        assert abs(getattr(ca, f) - getattr(cb, f)) <= 1e-12, f
    assert a.notes == b.notes
    assert (np.isnan(a.smoothing) and np.isnan(b.smoothing)) or a.smoothing == b.smoothing


def _fast_and_plain(gen, scenes, **options):
    """``generate_batch`` of ``gen`` (the fast paths) and of its plain_reference on ``scenes``,
    compared row by row (_same); the fast batch."""
    from jaxexo.inference.generator import plain_reference
    from jaxexo.physics.scenarios import batch_options

    args = batch_options(scenes)
    obstacles = [s.obstacle for s in scenes]
    fast = gen.generate_batch(obstacles, **args, **options)
    ref = plain_reference(gen).generate_batch(obstacles, **args, **options)
    assert len(fast) == len(ref) == len(scenes)
    for a, b in zip(fast, ref):
        _same(a, b)
    return fast


@pytest.mark.slow
def test_fast_generation_matches_the_reference_on_thousands_of_scenes(trained_run, tmp_path):
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.inference.generator import plain_reference
    from jaxexo.inference.scenarios import sample_scenarios

    from test_selection import policy_that_pushes_into_the_ground

    gen = TrajectoryGenerator.load(trained_run / "policy.npz")
    sc = sample_scenarios(gen.config, 2000, seed=7)
    assert _fast_and_plain(gen, sc).ok.any()
    # Failing swings and the fallback are compared too, built to fail rather than hoped for from the
    # trained policy: the same policy made to push the heel into the ground never leaves the start,
    # so it never reaches the goal. Alone, every swing fails; with CFFTG's fallback, each is CFFTG's
    # swing where that passes, else the failed RL swing.
    still = TrajectoryGenerator.load(
        policy_that_pushes_into_the_ground(tmp_path / "still.npz", trained_run / "policy.npz")
    )
    alone = _fast_and_plain(still, sc[:200], fallback=None)
    assert not alone.ok.any() and not alone.reached_goal.any()
    fell_back = _fast_and_plain(still, sc[:200])
    methods = np.array(fell_back.row_methods or (fell_back.method,) * len(fell_back))
    assert np.all((methods == "cfftg-fallback") | ~fell_back.ok)
    assert np.any(methods == "cfftg-fallback")
    plain = plain_reference(gen)
    for fallback in ("cfftg", None):
        for s in sc[:1000]:
            kw = s.options()
            _same(
                gen.generate(s.obstacle, fallback=fallback, **kw),
                plain.generate(s.obstacle, fallback=fallback, **kw),
            )


def test_pruned_point_clearances_keep_the_exact_minimum():
    rng = np.random.default_rng(2)
    kinds = [
        geometry.Obstacle.rectangle,
        geometry.Obstacle.triangle,
        geometry.Obstacle.half_ellipse,
    ]
    for n in (1, 2, 7, 60, 100):
        rows = []
        for i, path in enumerate(_random_paths(rng, 600, n)):
            ob = kinds[i % 3](
                rng.uniform(0.02, 0.25), rng.uniform(0.02, 0.25), center_y=rng.uniform(0.35, 0.55)
            )
            rows.append((path, ob.outline))
        for k in range(3):  # one outline size per call
            path = np.stack([p for p, _ in rows[k::3]])
            outline = np.stack([o for _, o in rows[k::3]])
            c_full = geometry.foot_clearance(np, path, FOOT, outline[:, None])
            # the box bound is a lower bound wherever it is positive, and then the foot is outside
            box = swept.box_lower_bound(path, FOOT, outline)
            pos = box > 0.0
            assert np.all(box[pos] <= c_full[pos] + 1e-12) and np.all(c_full[pos] > 0.0)
            c, sw = swept.path_clearance_pruned(path, FOOT, outline)
            if n == 1:
                np.testing.assert_array_equal(c, c_full)
                continue
            full = swept.path_swept_clearance(np, path, FOOT, outline, c_full)
            assert np.array_equal(sw.min(axis=1), full.min(axis=1))
            assert np.array_equal(np.argmin(sw, axis=1), np.argmin(full, axis=1))
            assert np.all(sw <= full + 1e-12)
            assert np.all((c == c_full) | ((c <= c_full + 1e-12) & (c > 0.0)))
            assert np.all(
                sw[sw != full] > full.min(axis=1, keepdims=True).repeat(n - 1, 1)[sw != full]
            )


def test_generate_batch_runs_blas_on_one_thread_and_restores_it(tmp_path, monkeypatch):
    """generate_batch limits BLAS to one thread while it runs (jaxexo.inference.blas), puts the
    process's setting back afterwards, and ``batch_blas_threads = None`` leaves BLAS alone; the
    trajectories are the same either way."""
    pytest.importorskip("jax")
    from jaxexo.inference import Obstacle, TrajectoryGenerator, blas

    from test_inference import export_random, small_config

    gen = TrajectoryGenerator.load(
        export_random(tmp_path / "p.npz", small_config(hidden=[16]), seed=1)
    )
    before = blas.blas_threads()
    assert before, "threadpoolctl (a jaxexo dependency) finds no BLAS in this process"
    seen = []
    rollout_batch = gen.rollout_batch

    def spy(scenes, *args):
        seen.append(blas.blas_threads())
        return rollout_batch(scenes, *args)

    monkeypatch.setattr(gen, "rollout_batch", spy)
    obstacles = [Obstacle.named("triangle"), Obstacle.named("base1"), Obstacle.named("half_circle")]
    limited = gen.generate_batch(obstacles)
    assert seen == [[1] * len(before)]
    assert blas.blas_threads() == before
    free_gen = gen.with_options(batch_blas_threads=None)
    monkeypatch.setattr(free_gen, "rollout_batch", spy)
    free = free_gen.generate_batch(obstacles)
    assert seen[-1] == before
    np.testing.assert_array_equal(limited.heel, free.heel)
    np.testing.assert_array_equal(limited.ok, free.ok)


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5, 8, 9, 16, 17])
def test_chained_reductions_equal_numpys_reductions(k):
    """geometry.min_last / any_last / odd_last (chains of elementwise operations over a short last
    axis) against NumPy's own reductions, bit for bit, NaN and signed zeros included."""
    rng = np.random.default_rng(k)
    for shape in ((k,), (7, k), (3, 5, k), (2, 4, 6, k)):
        x = rng.normal(size=shape)
        x[rng.uniform(size=shape) < 0.1] = 0.0
        x[rng.uniform(size=shape) < 0.05] = -0.0
        x[rng.uniform(size=shape) < 0.02] = np.nan
        b = rng.uniform(size=shape) < 0.3
        np.testing.assert_array_equal(geometry.min_last(np, x), np.min(x, axis=-1))
        assert np.array_equal(np.signbit(geometry.min_last(np, x)), np.signbit(np.min(x, axis=-1)))
        np.testing.assert_array_equal(geometry.any_last(np, b), np.any(b, axis=-1))
        np.testing.assert_array_equal(geometry.odd_last(np, b), np.sum(b, axis=-1) % 2 == 1)
        if len(shape) >= 2:
            np.testing.assert_array_equal(
                geometry.min_last(np, x, axes=2), np.min(x, axis=(-2, -1))
            )
            np.testing.assert_array_equal(
                geometry.any_last(np, b, axes=2), np.any(b, axis=(-2, -1))
            )


def test_chained_reductions_under_jax_jit():
    jax = pytest.importorskip("jax")
    jnp = jax.numpy
    rng = np.random.default_rng(0)
    x = rng.normal(size=(6, 4, 5)).astype(np.float32)
    b = rng.uniform(size=(6, 5)) < 0.5
    got = jax.jit(
        lambda a, c: (
            geometry.min_last(jnp, a, axes=2),
            geometry.any_last(jnp, c),
            geometry.odd_last(jnp, c),
        )
    )(x, b)
    np.testing.assert_array_equal(np.asarray(got[0]), x.min(axis=(-2, -1)))
    np.testing.assert_array_equal(np.asarray(got[1]), b.any(axis=-1))
    np.testing.assert_array_equal(np.asarray(got[2]), b.sum(axis=-1) % 2 == 1)
