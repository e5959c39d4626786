"""The proof per polynomial piece (jaxexo.swing.limit_proof): the bounds on |q'|, |q''|, |q'''| are
never below the curve, against evaluations independent of the composition (curve.joints_at: the
law and the path evaluated at each instant, then the chain rule): exactly on a hand-made curve
whose maxima are known in closed form, and at 100 kHz (and on both sides of every piece's ends)
on the timed swings of both generators, per piece and per swing; and a swing within the limits is
within them at every instant. JAXEXO_PROOF_SCALE=k multiplies the number of scenes (the CI run
times about 230 swings; a run at scale 10, about 2,300, is quoted in docs/device-timing.md)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics.scenarios import batch_options
from jaxexo.swing.curve import JointPath, TimeLaw, cubic_paths, joints_at, law_from_speeds
from jaxexo.swing.limit_proof import ROUNDING, curve_bounds
from jaxexo.swing.timing import time_swings

from benchlib.scenes import safety_sets
from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
SCALE = int(os.environ.get("JAXEXO_PROOF_SCALE", "1"))
SCENES = 40 * SCALE  # per benchmark set and generator (three sets)
DENSE_HZ = 100_000.0
# A dense value may exceed its piece's bound by the bound's own rounding slack at most (the
# bound's ends are the curve's values there, to rounding).
SLACK = 1.0 + ROUNDING


def _dense(path, law, rate=DENSE_HZ, extra=()):
    """Times from 0 to the end at ``rate`` and at ``extra``, the curve's s there, and |q'|, |q''|,
    |q'''| (3, J, n)."""
    t = np.unique(
        np.concatenate([np.arange(0.0, law.duration, 1.0 / rate), [law.duration], *extra])
    )
    ((s, d),) = joints_at([path], [law], [t])
    return t, s, np.abs(np.stack([x.T for x in d[1:]]))


def _sides(bound, duration):
    """Both sides of every piece's ends, a hair inside the piece (where its own cubic holds)."""
    hair = 1e-10 * duration
    return (
        np.clip(np.concatenate([bound.t0 + hair, bound.t1 - hair]), 0.0, duration),
        bound.t[1:-1],
    )


def _check_pieces(bound, path, t, s, dense, duration):
    """Every instant against its own piece: the pair of the law piece holding t (either one on a
    breakpoint, to a hair) with the path piece holding the curve's s there (as curve.paths_at
    finds it). The pair must exist, hold t in its span, and bound the curve there. Returns the
    curve's largest value over its bound."""

    hair = 1e-12 * duration
    count = len(path.coef)
    own = np.clip(np.searchsorted(path.knots, s, side="right") - 1, 0, count - 1)
    # Each pair's law piece (pairs are sorted by it, then by path piece): the one its span's
    # middle is in.
    law = np.searchsorted(bound.t, 0.5 * (bound.t0 + bound.t1), side="right") - 1
    keys = law * count + bound.piece
    assert np.all(np.diff(keys) > 0)
    allowed = np.zeros_like(dense)
    found = np.zeros(len(t), bool)
    for li in (np.searchsorted(bound.t, t, side="left"), np.searchsorted(bound.t, t) - 1):
        key = np.clip(li, 0, law[-1]) * count + own
        at = np.minimum(np.searchsorted(keys, key), len(keys) - 1)
        ok = (keys[at] == key) & (bound.t0[at] - hair <= t) & (t <= bound.t1[at] + hair)
        found |= ok
        allowed = np.maximum(allowed, np.where(ok, bound.bound[:, :, at], 0.0))
    assert found.all(), t[~found][:5]
    ratio = float((dense / np.maximum(allowed, 1e-300)).max())
    assert ratio <= SLACK, ratio
    return ratio


def _triangle_law(big_t, window, nodes=401):
    """The speed v(t) a triangle 0 -> V at T/2 -> 0 at T (area 1), with many collinear nodes (so
    that the law's pieces are short), averaged over ``window``."""
    t = np.linspace(0.0, big_t, nodes)
    v = (2.0 / big_t) * (1.0 - np.abs(2.0 * t / big_t - 1.0))
    return TimeLaw(t, v, window)


def test_hand_made_curve_maxima_known_in_closed_form():
    """A triangle of speed (peak V = 2/T, slope a = 2V/T) averaged over w <= T/2: max s' =
    V (1 - w / 2T) (the window centred on the peak), max |s''| = a (both ends on one slope), max
    |s'''| = 2a / w (the window's ends on opposite slopes). On a straight joint path q = q0 + alpha
    s, split into pieces at knots that the law crosses inside its pieces, the bounds are those
    maxima times |alpha|: never below, and within 1e-4 (velocity: a parabola's top inside a
    piece), 1e-8 (acceleration: linear on a piece) and 1e-8 (jerk: constant; the rounding slack
    is 1e-9)."""
    big_t, w = 1.2, 0.05
    law = _triangle_law(big_t, w)
    alpha = np.array([0.8, -1.3, 0.05, -0.4])
    knots = np.array([0.0, 0.1234567, 0.3, 0.51, 0.5100001, 0.77, 1.0])
    coef = np.zeros((len(knots) - 1, 4, 4))
    coef[:, 0] = 0.2 + alpha * knots[:-1, None]
    coef[:, 1] = alpha
    path = JointPath(knots, coef)
    (b,) = curve_bounds([path], [law])
    v = 2.0 / big_t
    a = 2.0 * v / big_t
    exact = [v * (1.0 - w / (2.0 * big_t)), a, 2.0 * a / w]
    for k, (peak, tol) in enumerate(zip(b.peaks, (1e-4, 1e-8, 1e-8))):
        true = exact[k] * np.abs(alpha)
        assert np.all(peak >= true) and np.all(peak <= true * (1.0 + tol)), (k, peak / true)
    # The pieces' bounds against a 100 kHz evaluation, each piece on its own.
    t, s, dense = _dense(path, law, extra=_sides(b, law.duration))
    _check_pieces(b, path, t, s, dense, law.duration)


def test_many_knots_per_law_piece_and_a_curved_path():
    """A C2 joint path through a smooth curve with far more knots (at random spacing) than the law
    has pieces (several knots crossed inside one law piece) and a law from random speeds: every
    piece's bound holds at 100 kHz and on both sides of its ends, and the bound is within 5 % of
    the curve's maximum per joint (the law's pieces here are ten times longer than a swing's)."""

    rng = np.random.default_rng(7)
    n = 400
    knots = np.cumsum(np.append(0.0, rng.uniform(0.5, 1.5, n - 1)))
    knots /= knots[-1]
    phase, freq = rng.uniform(0.0, 6.0, 4), rng.uniform(2.0, 9.0, 4)
    q = np.sin(freq * knots[:, None] + phase)[None]
    (path,) = cubic_paths(knots[None], q)
    grid = np.linspace(0.0, 1.0, 41)
    speeds = rng.uniform(0.5, 2.0, 41)
    speeds[0] = speeds[-1] = 0.0
    law = law_from_speeds(grid, speeds, np.zeros(40), 0.02)
    (b,) = curve_bounds([path], [law])
    assert len(b.t0) > 2 * (len(b.t) - 1)  # most law pieces cross knots
    t, s, dense = _dense(path, law, extra=_sides(b, law.duration))
    _check_pieces(b, path, t, s, dense, law.duration)
    top = dense.max(axis=2)
    assert np.all(np.stack(b.peaks) >= top) and np.all(np.stack(b.peaks) <= 1.05 * top)


@pytest.fixture(scope="module")
def timed():
    """The safe swings of RL alone and CFFTG on the three benchmark sets, timed at 100 Hz."""
    rl = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(rl.config)
    out = {"rl": [], "cfftg": []}
    for scenes in safety_sets(rl.config, SCENES).values():
        obs = [s.obstacle for s in scenes]
        kw = batch_options(scenes)
        out["rl"] += [t for t in rl.generate_batch(obs, fallback=None, **kw) if t.ok]
        out["cfftg"] += [t for t in cf.generate_batch(obs, **kw) if t.ok]
    return {g: time_swings(trajs, rl.config, rate=100.0) for g, trajs in out.items()}


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_bounds_never_below_the_curve_at_100_khz(timed, method):
    """Every timed swing: each piece's bound (the final curve's, proved again) at or above the
    curve at 100 kHz and on both sides of every piece's ends; the swing's peaks at or above the
    whole curve's maxima; and where the swing is within the limits, no instant over the planned
    limits. The bound is tight: per swing and order, the largest bound over the limits within
    5 % of the curve's largest value over them, 0.1 % at the median."""
    swings = timed[method]
    assert len(swings) >= 90 * SCALE
    tight = []
    for sw in swings:
        path, law = sw.curve.path, sw.curve.law
        (b,) = curve_bounds([path], [law])
        t, s, dense = _dense(path, law, extra=_sides(b, law.duration))
        _check_pieces(b, path, t, s, dense, law.duration)
        top = dense.max(axis=2)  # (3, J)
        peaks = np.stack([sw.peak_velocity, sw.peak_acceleration, sw.peak_jerk])
        assert np.all(top <= peaks * SLACK), (top / peaks).max()
        lim = sw.limits.planned()
        limits = np.array([lim.velocity, lim.acceleration, lim.jerk])
        if sw.within_limits:
            assert np.all(top <= limits), (top / limits).max()
        tight.append((peaks / limits).max(axis=1) / (top / limits).max(axis=1))
    tight = np.array(tight)
    assert tight.min() >= 1.0 and tight.max() <= 1.05 and np.median(tight) <= 1.001


def test_a_batch_gives_each_curve_its_bounds_alone(timed):
    """curve_bounds of a batch (both generators) equals each curve's alone, bit for bit."""
    swings = timed["rl"][:9] + timed["cfftg"][:9]
    together = curve_bounds([s.curve.path for s in swings], [s.curve.law for s in swings])
    for s, b in zip(swings, together):
        (alone,) = curve_bounds([s.curve.path], [s.curve.law])
        np.testing.assert_array_equal(alone.bound, b.bound)
        np.testing.assert_array_equal(alone.t0, b.t0)
        np.testing.assert_array_equal(alone.piece, b.piece)
        for x, y in zip(alone.peaks, b.peaks):
            np.testing.assert_array_equal(x, y)
