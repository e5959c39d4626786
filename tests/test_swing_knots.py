"""The swing in few pieces (jaxexo.swing.knots, jaxexo.swing.timing): the joint path through the
few joint samples its geometry needs stays within the tolerance of every joint sample, heel in
metres and joints in radians, by an independent evaluation (SciPy's not-a-knot spline and the forward
kinematics written out here), on hundreds of swings of both generators; its knots are few; and the
passes' cells hold the acceleration limits at both ends, against a plain bisection."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from jaxexo.baselines import CFFTG
from jaxexo.config import scalar_params
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics.scenarios import batch_options
from jaxexo.swing import knots, time_law
from jaxexo.swing.curve import chord_knots, cubic_paths, cubic_paths_ragged, distinct_samples
from jaxexo.swing.timing import _joint_paths, _joint_samples, time_swings

from benchlib.scenes import safety_sets
from conftest import ROOT
from test_swing_timing import _passes, joint_xmax

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"


@pytest.fixture(scope="module")
def samples():
    """Per generator, the safe swings of the three benchmark sets (60 scenes each) as the timing
    sees them: (swing, its joint samples less the near-repeats, their chord-length parameters)."""
    rl = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(rl.config)
    sp = scalar_params(rl.config)
    out = {"rl": [], "cfftg": []}
    for scenes in safety_sets(rl.config, 60).values():
        obs = [s.obstacle for s in scenes]
        kw = batch_options(scenes)
        for name, batch in (
            ("rl", rl.generate_batch(obs, fallback=None, **kw)),
            ("cfftg", cf.generate_batch(obs, **kw)),
        ):
            for t in batch:
                if t.ok:
                    q = _joint_samples(sp, t)
                    q = q[distinct_samples(q)]
                    out[name].append((t, q, chord_knots(q)))
    return sp, out


def _heel(q: np.ndarray, lengths, pivot_y: float) -> np.ndarray:
    """The swing heel (n, 2) of joints q (n, 4), written out: from the pivot heel up the stance
    shank and thigh to the hip, down the swing thigh and shank (segment angles measured from the
    downward vertical, hip_swing + knee_swing for the swing shank)."""
    thigh, shin = lengths
    down = lambda a: np.stack([np.sin(a), -np.cos(a)], axis=-1)  # noqa: E731
    hip = -thigh * down(q[:, 2]) - shin * down(q[:, 2] + q[:, 3])
    return hip + thigh * down(q[:, 0]) + shin * down(q[:, 0] + q[:, 1]) + [pivot_y, 0.0]


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_the_few_knot_path_stays_within_its_tolerance_of_every_joint_sample(samples, method):
    """Per swing: the path is SciPy's not-a-knot spline through its knots, which are joint samples
    (both ends among them); at every joint sample the heel (by the kinematics written out here)
    is within TOL_HEEL and each joint within TOL_JOINT; between the samples, on a grid 20 times
    finer, within TOL_HEEL and 1.5 TOL_JOINT of the spline through every sample (the timing's path
    before, measured: 0.87 and 1.17 of them), and the heel never lower than that path's (or the
    floor)."""
    sp, out = samples
    lengths = (sp.thigh, sp.shin)
    assert len(out[method]) > 150
    worst = np.zeros(4)
    for t, q, s in out[method]:
        path = knots.few_knot_path(q, s, lengths)
        at = np.searchsorted(s, path.knots)
        assert at[0] == 0 and at[-1] == len(s) - 1
        np.testing.assert_array_equal(s[at], path.knots)  # knots are samples' parameters
        few = CubicSpline(path.knots, q[at], bc_type="not-a-knot")
        fine = np.linspace(0.0, 1.0, 20 * len(s) + 1)
        np.testing.assert_allclose(path.derivatives(fine, 0)[0], few(fine), rtol=0, atol=1e-9)
        heel_err = np.linalg.norm(_heel(few(s), lengths, 0.0) - _heel(q, lengths, 0.0), axis=1)
        every = CubicSpline(s, q, bc_type="not-a-knot")
        y = t.scene.pivot_y
        gap = _heel(few(fine), lengths, y) - _heel(every(fine), lengths, y)
        between = np.linalg.norm(gap, axis=1)
        worst = np.maximum(
            worst,
            [
                heel_err.max() / knots.TOL_HEEL,
                np.abs(few(s) - q).max() / knots.TOL_JOINT,
                between.max() / knots.TOL_HEEL,
                np.abs(few(fine) - every(fine)).max() / (1.5 * knots.TOL_JOINT),
            ],
        )
        low = min(_heel(every(fine), lengths, y)[:, 1].min(), 0.0)
        assert _heel(few(fine), lengths, y)[:, 1].min() >= low - 1e-12
    assert np.all(worst <= 1.0), worst


def test_the_knots_are_few(samples):
    """A few dozen knots per swing, not the ~200 joint samples: median at most 70 and at most 100
    for either generator (the first knots every STRIDE-th sample, then the rounds; measured on the
    fixed benchmark swings: medians 64 RL / 55 CFFTG, at most 91), and the passes' grid of
    GRID_MIN + 1 points unless a path has more pieces."""
    sp, out = samples
    for method, rows in out.items():
        plans = _joint_paths([t for t, _, _ in rows], sp, [q for _, q, _ in rows])
        counts = np.array([len(p.path.knots) for p in plans])
        sizes = np.array([len(q) for _, q, _ in rows])
        assert np.median(counts) <= 70 and counts.max() <= 100, (method, counts.max())
        assert np.median(sizes) > 2 * np.median(counts)
        assert all(len(p.view.s) == 193 for p in plans if len(p.path.knots) <= 65)


def _plain_passes(dq, ddq, xmax, amax, ds):
    """The passes written out plainly, each cell's s'' within the acceleration limits at both of
    its ends, the largest speed found by bisection on the conditions themselves."""

    def interval(j, x):
        lo = (-amax - ddq[j] * x) / dq[j]
        hi = (amax - ddq[j] * x) / dq[j]
        return np.minimum(lo, hi).max(), np.maximum(lo, hi).min()

    def largest(ok, top):
        if ok(top):
            return top
        a, b = 0.0, top
        for _ in range(200):
            m = 0.5 * (a + b)
            a, b = (m, b) if ok(m) else (a, m)
        return a

    k = len(xmax)
    reach = np.zeros(k)
    for j in range(k - 1, 0, -1):
        r = reach[j]
        # from x at j - 1 to r at j: s'' = (r - x) / (2 ds) >= L at both ends
        ok = lambda x: (r - x) / (2 * ds) >= max(interval(j, r)[0], interval(j - 1, x)[0])  # noqa: E731
        reach[j - 1] = largest(ok, xmax[j - 1])
    x = np.zeros(k)
    for j in range(k - 1):
        v = x[j]
        ok = lambda y: (y - v) / (2 * ds) <= min(interval(j, v)[1], interval(j + 1, y)[1])  # noqa: E731
        x[j + 1] = largest(ok, reach[j + 1])
    return x


def test_topp_with_both_ends_equals_a_plain_bisection_row_by_row_and_batched():
    """topp(both_ends=True): the row-by-row (Python floats) and the batched scans agree bit for
    bit, and both equal the passes written out with each cell's constant s'' checked against the
    acceleration limits at its entry and its exit (bisection), on paths whose joints all move."""
    rng = np.random.default_rng(3)
    b, k = time_law.SCALAR_ROWS + 4, 120
    dq = rng.uniform(0.5, 2.0, size=(b, k, 4)) * rng.choice([-1.0, 1.0], size=(b, k, 4))
    ddq = 5.0 * rng.normal(size=(b, k, 4))
    vmax, amax, ds = np.array([3.0, 4.0, 3.0, 4.0]), np.array([15.0, 20.0, 15.0, 20.0]), 1 / (k - 1)
    big, floor = _passes(dq, ddq, vmax, amax, ds, both_ends=True)
    small = np.concatenate(
        [
            _passes(dq[i : i + 1], ddq[i : i + 1], vmax, amax, ds, both_ends=True)[0]
            for i in range(b)
        ]
    )
    np.testing.assert_array_equal(big, small)
    plain_end = _passes(dq, ddq, vmax, amax, ds)[0]
    assert np.all(big <= plain_end * (1 + 1e-12)) and np.any(big < plain_end * (1 - 1e-6))
    for i in range(0, b, 9):
        xmax = joint_xmax(dq[i], ddq[i], vmax, amax)[0]
        np.testing.assert_allclose(
            big[i], _plain_passes(dq[i], ddq[i], xmax, amax, ds), rtol=1e-9, atol=1e-12
        )
    assert np.all(np.isfinite(floor)) and np.all(big >= 0)


@pytest.mark.parametrize("size", [1, 3, 5, 9])
def test_ragged_splines_equal_each_path_solved_alone(size):
    """curve.cubic_paths_ragged (the batch's few-knot rounds: systems of different sizes padded to
    one) gives each path bit for bit what cubic_paths gives it alone, for batches solved as Python
    floats (up to 4) and vectorised."""
    rng = np.random.default_rng(size)
    for _ in range(25):
        ks, qs = [], []
        for _ in range(size):
            n = int(rng.integers(4, 60))
            k = np.sort(rng.uniform(0.0, 1.0, n))
            ks.append((k - k[0]) / (k[-1] - k[0]))
            qs.append(rng.normal(size=(n, 4)))
        for k, q, p in zip(ks, qs, cubic_paths_ragged(ks, qs)):
            (alone,) = cubic_paths(k[None], q[None])
            np.testing.assert_array_equal(p.knots, alone.knots)
            np.testing.assert_array_equal(p.coef, alone.coef)


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_a_rounding_of_the_heel_leaves_the_knots_and_the_timed_swing(samples, method):
    """The knots are chosen from the samples' places and the spline's deviation, not from their
    fourth differences: the stance leg's inverse kinematics (its knee nearly straight mid-swing)
    turns a 1e-16 m change of the heel into 1e-7 rad of joint samples, which moved knots chosen from
    an error estimate, and with them the timed swing by up to 1e-2 rad or a control period (36 of
    tests/reference_outputs.py's 400 timed swings). The heel moved by 16 ulps: the same knots, the
    same sample count, joint angles within 1e-4 rad."""
    sp, out = samples
    rng = np.random.default_rng(7)
    rows = out[method][:60]
    trajs = [t for t, _, _ in rows]
    moved = []
    for t in trajs:
        heel = np.array(t.heel, np.float64)
        step = 16 * np.finfo(np.float64).eps * np.abs(heel).max()
        heel[1:-1] += step * rng.choice([-1.0, 1.0], heel[1:-1].shape)
        moved.append(dataclasses.replace(t, heel=heel))
    config = TrajectoryGenerator.load(POLICY).config
    for a, b in zip(time_swings(trajs, config), time_swings(moved, config)):
        assert len(a.curve.path.knots) == len(b.curve.path.knots)
        np.testing.assert_allclose(a.curve.path.knots, b.curve.path.knots, rtol=0, atol=1e-9)
        assert len(a.time) == len(b.time) and a.ok == b.ok
        np.testing.assert_allclose(a.joint_angles, b.joint_angles, rtol=0, atol=1e-4)
