"""jaxexo.swing.clearing: the thesis spline corrected to keep the margin and to move forward,
checked against an independent dense look (point clearances of the foot at 40 positions per sample
interval, jaxexo.physics.geometry only) and against the plain spline where no correction is needed."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.physics import geometry, swept
from jaxexo.swing import smoothing as sm
from jaxexo.swing.clearing import clear_smooth

FOOT = 0.20
MARGIN = 0.02


def hugging_path(rng, outline, start=0.0, goal=0.75, hug=0.025, step=0.03):
    """A raw agent-like path: 3 cm moves in 10-degree directions, up beside the obstacle, along its top
    at about ``hug`` above it, down to the goal (what a shielded policy does)."""
    top = outline[:, 1].max()
    left = outline[:, 0].min()
    angles = np.deg2rad(np.arange(0, 360, 10))
    dirs = np.stack([np.cos(angles), np.sin(angles)], -1)
    pts = [np.array([start, 0.0])]
    h = pts[0]
    for _ in range(100):
        if abs(h[0] - goal) < 0.02 and h[1] < 0.01:
            break
        over = h[0] + FOOT > left - hug and h[0] < outline[:, 0].max() + hug
        want_z = (
            top + hug + rng.uniform(0, 0.01)
            if (over or h[0] + FOOT + 0.06 > left) and h[0] < goal - 0.15
            else 0.0
        )
        target = np.array([min(h[0] + 0.06, goal), want_z])
        d = target - h
        k = np.argmax(dirs @ d / max(np.linalg.norm(d), 1e-9))
        if dirs[k, 0] < 0:
            k = 9 if d[1] > 0 else 27
        h = np.array([h[0] + step * dirs[k, 0], max(h[1] + step * dirs[k, 1], 0.0)])
        pts.append(h)
    return np.array(pts)


def dense_min_clearance(path, outline, per=40):
    t = np.linspace(0.0, 1.0, per, endpoint=False)
    seg = path[:-1, None, :] + t[None, :, None] * (path[1:, None, :] - path[:-1, None, :])
    pts = np.concatenate([seg.reshape(-1, 2), path[-1:]])
    return float(geometry.foot_clearance(np, pts, FOOT, outline[None]).min())


def scenes(n, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        w, h = rng.uniform(0.04, 0.22), rng.uniform(0.05, 0.25)
        c = rng.uniform(0.33, 0.42)
        kind = rng.integers(3)
        ob = (
            geometry.Obstacle.rectangle(w, h, center_y=c)
            if kind == 0
            else geometry.Obstacle.triangle(w, h, center_y=c)
            if kind == 1
            else geometry.Obstacle.half_ellipse(w, h, center_y=c)
        )
        outline = np.asarray(ob.outline, float)
        yield outline, hugging_path(rng, outline)


def test_corrected_curves_keep_the_margin_under_a_dense_look():
    plain_cut, fixed = 0, 0
    for outline, raw in scenes(120):
        p0 = sm.smooth_paths([raw], 100, sm.DEFAULT_SMOOTHING)[0]
        if dense_min_clearance(p0, outline) < MARGIN:
            plain_cut += 1
        path, dev, rounds = clear_smooth(raw, outline, FOOT, MARGIN)
        assert path.shape == (100, 2) and np.all(np.isfinite(path)) and dev >= 0.0
        np.testing.assert_array_equal(path[0], raw[0])
        np.testing.assert_array_equal(path[-1], sm.distinct(raw)[-1])
        c = dense_min_clearance(path, outline) - dev
        back = float(np.max(np.maximum.accumulate(path[:, 0]) - path[:, 0]))
        if c >= MARGIN and back <= 1e-9:
            fixed += 1
        else:
            # a curve that still fails is one the corrections gave up on (it goes to the retries)
            assert rounds >= 1
    # the plain spline cuts the margin on most of these paths; the corrected one almost never
    assert plain_cut >= 60
    assert fixed >= 114


def test_no_correction_where_the_plain_spline_keeps_the_margin():
    outline = np.asarray(geometry.Obstacle.rectangle(0.05, 0.05, center_y=0.4).outline, float)
    raw = np.array(
        [
            [0.0, 0.0],
            [0.1, 0.08],
            [0.2, 0.14],
            [0.3, 0.17],
            [0.4, 0.18],
            [0.5, 0.17],
            [0.6, 0.13],
            [0.7, 0.06],
            [0.75, 0.0],
        ]
    )
    path, dev, rounds = clear_smooth(raw, outline, FOOT, MARGIN)
    ref, ref_dev = sm.smooth_paths([raw], 100, sm.DEFAULT_SMOOTHING, with_deviation=True)
    assert rounds == 0
    np.testing.assert_allclose(path, ref[0], atol=1e-12)
    assert dev == pytest.approx(ref_dev[0], abs=1e-15)


@pytest.mark.parametrize(
    "raw",
    [
        np.array([[0.0, 0.0], [0.03, 0.0], [0.06, 0.0]]),  # too short for a spline
        np.array([[0.0, 0.0]] * 5),  # stood still
        np.array(
            [[0.0, 0.0], [0.25, 0.0], [0.5, 0.0], [0.75, 0.0], [1.0, 0.0]]
        ),  # straight through
    ],
)
def test_degenerate_paths_stay_finite(raw):
    outline = np.asarray(geometry.Obstacle.rectangle(0.1, 0.1, center_y=0.5).outline, float)
    path, dev, _ = clear_smooth(raw, outline, FOOT, MARGIN)
    assert np.all(np.isfinite(path)) and np.isfinite(dev)
    assert np.max(np.abs(path - sm.distinct(raw)[0])) <= 1.5


def test_two_samples_have_nothing_to_move():
    outline = np.asarray(geometry.Obstacle.triangle(0.2, 0.2, center_y=0.35).outline, float)
    raw = np.array([[0.0, 0.0], [0.05, 0.1], [0.25, 0.21], [0.45, 0.21], [0.65, 0.1], [0.70, 0.0]])
    path, dev, rounds = clear_smooth(raw, outline, FOOT, MARGIN, n_points=2)
    np.testing.assert_array_equal(path, [raw[0], raw[-1]])


def test_a_smoothed_path_is_accepted_with_headroom_above_the_margin():
    """The generator accepts a retried path only ACCEPT_HEADROOM above the margin (so that its
    device-ready retiming, which resamples an interpolant of the samples, keeps the margin too): a path
    whose guaranteed clearance is between the margin and margin + headroom is sent on to the spline's
    correction, one above is accepted, one below is not."""
    from jaxexo.swing.finish import ACCEPT_HEADROOM
    from jaxexo.swing.trajectory import passes

    from test_fast_shield import _random_generator

    gen = _random_generator()
    m, h = gen.sp.min_clearance, ACCEPT_HEADROOM
    assert 0 < h < 1e-3
    low = np.array([m + 2 * h, m + 0.5 * h, m - 0.5 * h, m + 2 * h])
    dev = np.array([0.0, 0.0, 0.0, 1.5 * h])
    back = np.zeros(4)
    np.testing.assert_array_equal(passes(gen.sp, low, dev, back, h), [True, False, False, False])


# --------------------------------------------------------------------------------------------
# Many paths corrected together, the pruned clearances, the stacked dual solve
# --------------------------------------------------------------------------------------------


def _mixed_scenes(n, seed):
    """Agent-like hugging paths and noisy arcs (some through the obstacle, some too short for a
    spline, some with repeated points) on rectangles, triangles and half-ellipses."""
    rng = np.random.default_rng(seed)
    out = []
    for i, (outline, raw) in enumerate(scenes(n, seed)):
        if i % 4 == 3:  # a noisy arc instead: heavier corrections, backward wiggles
            m = int(rng.integers(2, 45))
            u = np.linspace(0.0, 1.0, m)
            raw = np.column_stack(
                [
                    0.75 * u + rng.normal(0, 0.01, m),
                    np.maximum(
                        rng.uniform(0.05, 0.3) * np.sin(np.pi * u) + rng.normal(0, 0.01, m), 0
                    ),
                ]
            )
            if m > 5:
                raw[m // 2] = raw[m // 2 - 1]
        out.append((outline, raw))
    return out


def test_many_paths_corrected_together_equal_each_corrected_alone_and_the_reference():
    """clear_rows (the paths' rounds together, pruned clearances) against exact_clear_rows (every
    move's swept clearance exact: the same curves, bit for bit, since the shortfalls that steer the
    correction are the same numbers) and against each path corrected on its own (the same curve, bit
    for bit: the stacked products and the dual systems, solved at their own size, do the same
    arithmetic in any batch)."""
    from jaxexo.swing.clearing import clear_rows, exact_clear_rows

    rows = _mixed_scenes(400, seed=11)
    outlines, raws = [o for o, _ in rows], [r for _, r in rows]
    fast = clear_rows(raws, outlines, FOOT, MARGIN)
    ref = exact_clear_rows(raws, outlines, FOOT, MARGIN)
    corrected = 0
    for (outline, raw), a, b in zip(rows, fast, ref):
        np.testing.assert_array_equal(a.path, b.path)
        assert a.deviation == b.deviation and a.rounds == b.rounds
        one = clear_smooth(raw, outline, FOOT, MARGIN)
        np.testing.assert_array_equal(a.path, one[0])
        assert a.deviation == one[1] and a.rounds == one[2]
        corrected += a.rounds > 0
        if a.move_clearance is not None:
            # the last round's clearances are those of the returned curve: minimum and place exact
            full = swept.path_swept_clearance(np, a.path, FOOT, outline)
            assert a.move_clearance.min() == full.min() and np.argmin(
                a.move_clearance
            ) == np.argmin(full)
            assert np.all(a.move_clearance <= full + 1e-12)
    assert corrected > 200


def test_pruned_clearances_are_exact_under_the_threshold():
    """path_clearance_pruned(below=...): every move closer than its path's threshold is exact, every
    other one is reported at or above the threshold (and never above its exact value), the minimum
    and its place exact, against the full swept clearance on random paths."""
    rng = np.random.default_rng(5)
    kinds = [
        geometry.Obstacle.rectangle,
        geometry.Obstacle.triangle,
        geometry.Obstacle.half_ellipse,
    ]
    pruned = 0
    for k, kind in enumerate(kinds):
        for n in (2, 9, 100):
            paths, outlines = [], []
            for _ in range(200):
                u = np.linspace(0.0, 1.0, n)
                y = rng.uniform(-0.1, 0.1) + rng.uniform(0.6, 0.9) * u + rng.normal(0, 0.01, n)
                z = np.maximum(
                    rng.uniform(0, 0.35) * np.sin(np.pi * u) + rng.normal(0, 0.005, n), 0.0
                )
                paths.append(np.column_stack([y, z]))
                outlines.append(
                    kind(
                        rng.uniform(0.02, 0.25),
                        rng.uniform(0.02, 0.25),
                        center_y=rng.uniform(0.35, 0.55),
                    ).outline
                )
            path, outline = np.stack(paths), np.stack(outlines)
            below = rng.uniform(0.0, 0.08, len(path))
            c, sw = swept.path_clearance_pruned(path, FOOT, outline, below=below)
            full = swept.path_swept_clearance(np, path, FOOT, outline)
            exact = sw == full
            assert np.all(exact | (sw >= below[:, None]))
            assert np.all(exact[full < below[:, None]])
            assert np.all(sw <= full + 1e-12)
            np.testing.assert_array_equal(sw.min(axis=1), full.min(axis=1))
            np.testing.assert_array_equal(np.argmin(sw, axis=1), np.argmin(full, axis=1))
            pruned += int(np.sum(~exact))
    assert pruned > 1000


def test_stacked_dual_solve_equals_lstsq():
    """The dual's stacked solve (LU where the system is safely positive definite, lstsq's minimum-norm
    solution elsewhere) against np.linalg.lstsq on each active subsystem: well-conditioned, rank
    deficient (more constraints than freedoms) and repeated constraints, with inactive ones."""
    from jaxexo.swing.clearing import _solve_stack

    rng = np.random.default_rng(2)
    for rank, k in ((12, 8), (6, 10), (3, 9), (20, 20)):
        f = rng.normal(size=(50, k, rank))
        f[::5, 1] = f[::5, 0]  # a repeated constraint
        a = f @ f.transpose(0, 2, 1)
        b = rng.normal(size=(50, k))
        act = rng.uniform(size=(50, k)) < 0.8
        act[:, 0] = True
        for stack in (a, a[:1]):  # many systems, and one (its own branch)
            g = len(stack)
            x = _solve_stack(stack, b[:g], act[:g])
            for i in range(g):
                on = np.flatnonzero(act[i])
                ref = np.linalg.lstsq(stack[i][np.ix_(on, on)], b[i, on], rcond=None)[0]
                assert np.all(x[i, ~act[i]] == 0.0)
                sub = stack[i][np.ix_(on, on)]
                # the same solution where it is unique; the same least-squares fit either way
                np.testing.assert_allclose(
                    sub @ x[i, on], sub @ ref, rtol=0, atol=1e-6 * (1 + np.abs(b[i]).max())
                )
                if np.linalg.matrix_rank(sub) == len(on):
                    np.testing.assert_allclose(x[i, on], ref, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize(
    "args, match",
    [
        (dict(raws=[np.zeros((5, 2))], outlines=[]), "1 raw paths but 0 outlines"),
        (dict(n_points=1), "n_points"),
        (dict(n_points=True), "n_points"),
        (dict(margin=-0.01), "margin"),
        (dict(smoothing=float("nan")), "smoothing"),
        (dict(raws=[np.zeros((5, 3))]), r"raws\[0\]"),
        (dict(raws=[np.zeros((0, 2))]), r"raws\[0\]"),
        (dict(outlines=[np.zeros((1, 2))]), r"outlines\[0\]"),
    ],
)
def test_bad_input_to_clear_rows_is_refused(args, match):
    from jaxexo.swing.clearing import clear_rows

    outline = np.asarray(geometry.Obstacle.rectangle(0.1, 0.1, center_y=0.4).outline, float)
    kw = dict(
        raws=[np.array([[0.0, 0.0], [0.2, 0.1], [0.4, 0.2], [0.6, 0.1], [0.75, 0.0]])],
        outlines=[outline],
        foot_length=FOOT,
        margin=MARGIN,
        n_points=100,
        smoothing=0.005,
    )
    kw.update(args)
    with pytest.raises(ValueError, match=match):
        clear_rows(**kw)


def test_the_first_round_measures_the_requested_smoothings_own_spline():
    """Cleared.initial (the generator's one swing takes the requested smoothing from it when it passes)
    is smoothing.smooth_candidates' curve of that smoothing, bit for bit, with its deviation bound,
    and its clearances' minimum and place are the full swept clearance's."""
    from jaxexo.swing.clearing import clear_rows

    rows = _mixed_scenes(300, seed=21)
    got = clear_rows([r for _, r in rows], [o for o, _ in rows], FOOT, MARGIN)
    checked = 0
    for (outline, raw), g in zip(rows, got):
        m = len(sm.distinct(raw))
        if m < sm.DEGREE + 1:
            assert g.initial is None
            continue
        paths, dev = sm.smooth_candidates(raw, 100, [sm.DEFAULT_SMOOTHING, m * 0.004**2])
        p0, d0, c0, sw0 = g.initial
        np.testing.assert_array_equal(p0, paths[0])
        assert d0 == dev[0]
        full = swept.path_swept_clearance(np, p0, FOOT, outline)
        assert sw0.min() == full.min() and np.argmin(sw0) == np.argmin(full)
        if g.rounds == 0:
            np.testing.assert_array_equal(g.path, p0)
        checked += 1
    assert checked > 250


def test_one_systems_dual_is_the_stacked_dual_bit_for_bit():
    """_dual and _solve_same of one system (their one-row paths) against the same system solved
    among others (the general paths): the same multipliers and solutions, bit for bit, on
    well-conditioned, rank-deficient and repeated constraints, with inactive ones."""
    from jaxexo.swing.clearing import _dual, _solve_same

    rng = np.random.default_rng(8)
    one_row_only = 0
    for rank, k in ((12, 8), (6, 10), (3, 9), (20, 20), (2, 3)):
        f = rng.normal(size=(40, k, rank))
        f[::5, 1] = f[::5, 0]  # a repeated constraint
        a = f @ f.transpose(0, 2, 1)
        need = rng.normal(size=(40, k))
        valid = rng.uniform(size=(40, k)) < 0.9
        both = _dual(a, need, valid)
        solved = _solve_same(a, need)
        for i in range(len(a)):
            np.testing.assert_array_equal(
                _dual(a[i : i + 1], need[i : i + 1], valid[i : i + 1])[0], both[i]
            )
            np.testing.assert_array_equal(_solve_same(a[i : i + 1], need[i : i + 1])[0], solved[i])
            one_row_only += bool(np.any(both[i] > 0.0))
    assert one_row_only > 50
