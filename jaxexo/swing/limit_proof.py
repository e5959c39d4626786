"""A proof that a timed swing keeps its limits (NumPy only): per polynomial piece of the curve
q(t) = Q(S(t)), an upper bound on |q'|, |q''| and |q'''| that is never below their largest value
on the piece, vectorised over every piece of a batch of swings. Used by jaxexo.swing.curve_check;
the method and its measured tightness: docs/device-timing.md, "The limits proved per piece".

On a piece of time [c - H, c + H] where the law S and the path Q are each one cubic,
q(c + H sigma) = sum_j p_j sigma^j is a polynomial of degree 9 in sigma, composed exactly from the
Taylor coefficients of S at c and of Q at S(c): with u(sigma) = S(c + H sigma) - S(c) =
U1 sigma + U2 sigma^2 + U3 sigma^3, q = Q(S(c)) + G1 u + G2 u^2 + G3 u^3 (G1 = Q', G2 = Q''/2,
G3 = Q'''/6 at S(c)). For |sigma| <= 1, |d^k/dsigma^k sigma^j| <= j!/(j-k)!, and
d^k/dt^k = H^-k d^k/dsigma^k, so |q^(k)| <= H^-k sum_j j!/(j-k)! |p_j| at every instant of the
piece: the rows p_1..p_4 exactly, the small rows p_5..p_9 (higher powers of the short piece) by
the triangle inequality over their terms, with the largest of G2 and G3 over the joints.

The pieces: each piece of the law (between its breakpoints; a long one cut in equal parts) is
paired with every piece of the path its s range touches.
 Where it crosses a knot, each pair covers its side of the crossing (found on
the law's cubic, and widened by CROSS_WIDTH where the cubic is checked to be past the knot there),
or the whole law piece where that check fails: each instant's own pair covers it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from jaxexo.swing.curve import laws_at

# Relative slack on every bound, for rounding (and the same fraction of the curve's largest bound
# added where the curve nearly vanishes: ``_absolute``). The curve at an instant (curve.laws_at, paths_at)
# and the bound's coefficients are computed in float64 with relative errors of a few 1e-16 of
# their terms (sums of a few terms of the bound's size on pieces this short; the law's s' is a
# difference over its window: about 1e-14); the pieces' ends are known to an ulp of t, which
# 1e-9 of a piece's half-width covers many times over (widening a piece by 1e-9 of its
# half-width raises the bound by at most 9e-9 of itself, and the margin is applied to all nine
# rows). Measured (tests/test_limit_proof.py, 100 kHz): the curve reaches its bound less the slack
# times 1 + 1.3e-14 at most, where the end of a piece is its largest value.

ROUNDING = 1e-9
# A law piece is paired with every path piece within this of its s range (s in [0, 1]): the
# curve's s at an instant near a knot rounds to either side of it by far less.
S_SLACK = 1e-12
# Where a law piece crosses a knot: the crossing found by NEWTON_STEPS on the law's cubic from its
# chord's (S is nearly linear on a piece: one step leaves ~1e-6 of the piece), and each side's
# pair widened past it by CROSS_WIDTH of the law piece's half-width (in sigma), kept where the
# cubic there is S_SLACK past the knot (else the whole law piece: looser, never wrong).
NEWTON_STEPS = 4
CROSS_WIDTH = 1e-4
# Law pieces bounded in one vectorised step at most (the arrays are a few x 4 x pieces floats): a
# batch's memory stays bounded whatever its swings (a wandering one has tens of thousands).
GROUP_PIECES = 1 << 15
# A piece of the law longer than this fraction of its window is bounded in equal parts, at most
# MAX_PARTS (the window is the time scale on which the law's acceleration changes; the first and
# last pieces, and the slow stretches, are the long ones).
PIECE_FRACTION = 0.1

MAX_PARTS = 4


@dataclass(frozen=True)
class CurveBound:
    """A curve's proven bounds. Per piece i (a law piece paired with a path piece, sorted by law
    piece, then path piece): the span [t0[i], t1[i]] (N,) s where the pair may hold, its path
    piece (N,) (an index into the path's pieces) and the bounds (3, J, N) on |q-dot|, |q-ddot|,
    |q-dddot| over the span (rad/s, rad/s^2, rad/s^3); ``peaks``: their maxima over the pieces,
    (J,) each. ``t`` (L + 1,): the law's breakpoints, and ``s`` the path parameter there
    (non-decreasing): for maps between s and t."""

    t: np.ndarray
    s: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    piece: np.ndarray
    bound: np.ndarray
    peaks: tuple


def curve_bounds(paths, laws, since=None) -> list[CurveBound]:
    """The proven bounds of each curve (path, law): in groups of at most GROUP_PIECES law pieces
    (or one curve); each curve's bounds do not depend on the others (elementwise arithmetic, exact
    maxima), so a batch gives every curve what it gives it alone. ``since`` (one time per curve,
    s): only the law pieces that end after it (a replanned swing's, whose curve before the switch
    is the old swing's, already bounded)."""
    since = [None] * len(laws) if since is None else list(since)
    out, group, size = [], [], 0
    for i, law in enumerate(laws):
        n = 2 * MAX_PARTS * len(law.nodes)  # its pieces at most
        if group and size + n > GROUP_PIECES:
            out += _bounds(*([x[j] for j in group] for x in (paths, laws, since)))
            group, size = [], 0
        group.append(i)
        size += n
    return out + _bounds(*([x[j] for j in group] for x in (paths, laws, since)))


def _cat(xs):
    return xs[0] if len(xs) == 1 else np.concatenate(xs)


def _pairs(paths, lo, hi, counts):
    """Per pair of a law piece with a path piece it touches (sorted by law piece, then s): the law
    piece and the path piece (global indices into the concatenated pieces), and per law piece its
    number of pairs. A law piece spanning s in [lo, hi] touches the path pieces from the one holding
    lo - S_SLACK to hi + S_SLACK's. Searched curve by curve: the same comparisons alone as in a
    batch."""
    first, last, start, offset = [], [], 0, 0
    for path, n in zip(paths, counts):
        inner = path.knots[1:-1]
        first.append(inner.searchsorted(lo[start : start + n] - S_SLACK, side="right") + offset)
        last.append(inner.searchsorted(hi[start : start + n] + S_SLACK, side="right") + offset)
        start += n
        offset += len(path.coef)
    first, last = _cat(first), _cat(last)
    many = last - first
    if not many.any():  # no law piece crosses a knot
        return np.arange(len(first)), first, many + 1
    many += 1
    law = np.arange(len(first)).repeat(many)
    within = np.arange(len(law)) - (many.cumsum() - many).repeat(many)
    return law, first.repeat(many) + within, many


def _spans(law, knot, s, u, lo, hi):
    """Per pair (N,), the stretch [a, b] of its law piece's sigma in [-1, 1] where its path piece
    may hold: from the crossing of its first knot to that of the next (Newton's steps on the law's
    cubic from its chord's crossing), each widened by CROSS_WIDTH and kept only where the law's
    cubic there is S_SLACK past the knot (so the curve's own s, within rounding of the cubic's, is
    on the knot's side: S is non-decreasing); elsewhere the whole law piece. ``knot``: each pair's
    path piece's first knot; per law piece, ``s`` = S(c), ``u`` (3, L) = U1..U3, ``lo`` and ``hi``
    = S at its ends."""

    a, b = np.full(len(law), -1.0), np.full(len(law), 1.0)
    cross = np.flatnonzero(law[1:] == law[:-1]) + 1  # a pair whose knot its law piece crosses
    if not len(cross):
        return a, b
    li = law[cross]
    k = knot[cross]
    low = lo[li]
    x = (2.0 * (k - low)) / np.maximum(hi[li] - low, 1e-300) - 1.0
    f0 = s[li] - k
    u1, u2, u3 = u[:, li]
    for _ in range(NEWTON_STEPS):  # then Newton's steps on the cubic
        slope = u1 + x * (2.0 * u2 + 3.0 * u3 * x)
        x -= (f0 + x * (u1 + x * (u2 + x * u3))) / np.where(slope > 0.0, slope, np.inf)
    left, right = x - CROSS_WIDTH, x + CROSS_WIDTH
    ok_left = (left > -1.0) & (f0 + left * (u1 + left * (u2 + left * u3)) <= -S_SLACK)
    ok_right = (right < 1.0) & (f0 + right * (u1 + right * (u2 + right * u3)) >= S_SLACK)
    a[cross] = np.where(ok_left, left, -1.0)
    b[cross - 1] = np.where(ok_right, right, 1.0)
    return a, b


# The sigma coefficients of u^2 and u^3 (u = v1 sigma + v2 sigma^2 + v3 sigma^3) as sums of at
# most two products of a monomial of degree 2 (rows of _MONO2: v1^2, v1 v2, v2^2, v1 v3, v2 v3,
# v3^2) with a factor and an integer: per row of the result, (monomial, v index or 3 for 1, weight)
# for its two terms (weight 0: none). Rows: W2, W3, W4 and V3, V4 (the exact rows), then W5, W6,
# V5..V9 (the tails).
_MONO2 = (np.array([0, 0, 1, 0, 1, 2]), np.array([0, 1, 1, 2, 2, 2]))
_TERMS = np.array(
    [
        [[0, 3, 1], [0, 3, 0]],
        [[1, 3, 2], [0, 3, 0]],
        [[2, 3, 1], [3, 3, 2]],
        [[0, 0, 1], [0, 3, 0]],
        [[0, 1, 3], [0, 3, 0]],
        [[4, 3, 2], [0, 3, 0]],
        [[5, 3, 1], [0, 3, 0]],
        [[2, 0, 3], [0, 2, 3]],
        [[2, 1, 1], [1, 2, 6]],
        [[2, 2, 3], [5, 0, 3]],
        [[5, 1, 3], [0, 3, 0]],
        [[5, 2, 1], [0, 3, 0]],
    ]
)
# Per order k = 1..3, the weights j!/(j-k)! of p_1..p_4 (exact) and of the tail rows W5, W6 (for
# G2) and V5..V9 (for G3).
_EXACT = [np.array([math.perm(j, k) for j in range(k, 5)], np.float64)[:, None] for k in (1, 2, 3)]
_TAIL = np.array([[math.perm(j, k) for j in (5, 6, 5, 6, 7, 8, 9)] for k in (1, 2, 3)], np.float64)


def _series(v, half, g2, g3):
    """Per piece (N,), from the sigma coefficients v (3, N) of u, the half-width H and bounds on
    |G2| and |G3| over the joints: the rows the exact p_1..p_4 need, (U1, U2, U3, W2, W3, W4, V3,
    V4) (8, N), and per order k = 1..3 the weights of |p_k|..|p_4| in the bound,
    j!/(j-k)! (1 + ROUNDING) / H^k (rows, 1, N), and the tail, the rows p_5..p_9 (G2 W_j + G3 V_j)
    by the triangle inequality, scaled the same (N,)."""
    mono = v[_MONO2[0]] * v[_MONO2[1]]  # (6, N)
    ext = np.concatenate([v, np.ones((1, v.shape[1]))])  # v1, v2, v3, 1
    rows = np.empty((15, v.shape[1]))
    rows[0:3] = v
    t = _TERMS
    rows[3:] = mono[t[:, 0, 0]] * ext[t[:, 0, 1]] * t[:, 0, 2, None]
    rows[3:] += mono[t[:, 1, 0]] * ext[t[:, 1, 1]] * t[:, 1, 2, None]
    big = np.abs(rows[8:])  # W5, W6, V5..V9
    big[:2] *= g2
    big[2:] *= g3
    tails = np.add.reduce(big * _TAIL[:, :, None], axis=1)  # (3, N)
    inv = (1.0 + ROUNDING) / half
    weights = []
    for k in range(3):
        weights.append((_EXACT[k] * inv)[:, None, :])
        tails[k] *= inv
        inv = inv / half
    return rows[:8], weights, tails[:, None, :]


def _split(b: np.ndarray, window: float) -> np.ndarray:
    """Breakpoints ``b`` with each piece longer than PIECE_FRACTION of the law's ``window`` cut
    into equal parts that are not, MAX_PARTS at most (the same cubic on each part: a shorter
    part's bound is tighter, the Taylor terms beyond the linear one shrinking with its length
    squared)."""
    width = np.diff(b)
    parts = np.minimum(np.ceil(width / (PIECE_FRACTION * window)), MAX_PARTS)
    if not np.any(parts > 1):
        return b
    parts = parts.astype(np.int64)
    step = np.repeat(width / parts, parts)
    k = np.arange(int(parts.sum())) - np.repeat(np.cumsum(parts) - parts, parts)
    return np.append(np.repeat(b[:-1], parts) + k * step, b[-1])


def _from(b: np.ndarray, since) -> np.ndarray:
    """Breakpoints ``b`` from the piece holding ``since`` on (all of them for None)."""
    if since is None:
        return b
    return b[max(0, int(np.searchsorted(b, since, side="right")) - 1) :]


def _bounds(paths, laws, since) -> list[CurveBound]:
    """``curve_bounds`` of one group, in one vectorised step."""
    b = [_from(_split(law.breakpoints(), law.window), t) for law, t in zip(laws, since)]

    half = [0.5 * np.diff(x) for x in b]
    centre = [x[:-1] + h for x, h in zip(b, half)]
    lv = laws_at(laws, centre)  # s and its derivatives at the law pieces' middles
    s, s1, s2, s3 = lv[0] if len(lv) == 1 else (np.concatenate(x) for x in zip(*lv))
    h = _cat(half)
    u = np.empty((3, len(h)))  # U1..U3: u(sigma) = S(c + H sigma) - S(c)
    np.multiply(s1, h, out=u[0])
    np.multiply(0.5 * s2, h * h, out=u[1])
    np.multiply(s3 / 6.0, h**3, out=u[2])
    # S at each law piece's ends, from its cubic (S''' is constant on the piece).
    even, odd = s + u[1], u[0] + u[2]
    lo, hi = even - odd, even + odd
    counts = [len(x) - 1 for x in b]
    law, piece, many = _pairs(paths, lo, hi, counts)
    knot = _cat([p.knots[:-1] for p in paths])[piece]
    sa, sb = _spans(law, knot, s, u, lo, hi)
    # Each pair's own piece of time: sigma = m + r tau, tau in [-1, 1], the law's cubic re-centred
    # there (exactly itself where the pair is its law piece's only one: m = 0, r = 1).
    m, r = 0.5 * (sa + sb), 0.5 * (sb - sa)
    u1, u2, u3 = u[:, law]
    s_c = s[law] + m * (u1 + m * (u2 + m * u3))
    v = np.empty((3, len(law)))
    np.multiply(u1 + m * (2.0 * u2 + 3.0 * u3 * m), r, out=v[0])
    np.multiply(u2 + 3.0 * u3 * m, r * r, out=v[1])
    np.multiply(u3, r**3, out=v[2])
    # The path's Taylor coefficients at S there, from its piece's cubic (extended past its knots
    # by the span's widening at most): G1 = Q', G2 = Q'' / 2, G3 = Q''' / 6, each (J, N); for the
    # tail, bounds on |G2| and |G3| over the joints from the pieces' largest coefficients.
    coefs = _cat([p.coef for p in paths])
    most = np.abs(coefs[:, 2:]).max(axis=2)  # (P, 2)
    du = s_c - knot
    c2, c3 = most[piece].T
    exact, weights, tail = _series(v, h[law] * r, c2 + 3.0 * c3 * np.abs(du), c3)
    coef = coefs.transpose(1, 2, 0)[1:, :, piece]
    g3 = coef[2]
    g2 = coef[1] + (3.0 * du) * g3
    g1 = coef[0] + (coef[1] + g2) * du
    e = exact[:, None, :]
    a = np.empty((4, *g1.shape))  # |p_1| .. |p_4|: (4, J, N)
    np.multiply(g2, e[3:6], out=a[1:4])
    np.multiply(g1, e[0], out=a[0])
    a[1:3] += g1 * e[1:3]
    a[2:4] += g3 * e[6:8]
    np.abs(a, out=a)
    # Sums in a fixed order (a reduction over a leading axis adds its rows one by one): the same
    # bits whatever the number of pieces beside them.
    bound = np.empty((3, *g1.shape))
    for k in range(3):
        np.add.reduce(a[k:] * weights[k], axis=0, out=bound[k])
    bound += tail
    spans = (_cat(centre)[law] + h[law] * np.stack([sa, sb]), piece)
    return _records(paths, b, lo, hi, counts, many, spans, bound)


def _records(paths, b, lo, hi, counts, many, spans, bound) -> list[CurveBound]:
    """Each curve's CurveBound: its slice of the group's pieces (``spans``: their times (2, N) and
    path pieces (N,)), with ``_absolute``'s slack, and its peaks (exact maxima)."""
    (t0, t1), piece = spans
    if len(b) == 1:
        s_at = np.maximum.accumulate(np.append(lo, hi[-1]))
        bound, peak = _absolute(bound, bound.max(axis=2))
        return [CurveBound(b[0], s_at, t0, t1, piece, bound, peak)]
    sizes = np.add.reduceat(many, np.cumsum([0, *counts[:-1]]))
    starts = np.cumsum(sizes) - sizes
    peaks = np.maximum.reduceat(bound, starts, axis=2)  # (3, J, B)
    out, first, offset = [], 0, 0
    for j, (n, a, k) in enumerate(zip(counts, starts, sizes)):
        s_at = np.maximum.accumulate(np.append(lo[first : first + n], hi[first + n - 1]))
        own, peak = _absolute(bound[:, :, a : a + k], peaks[:, :, j])
        out.append(
            CurveBound(
                b[j], s_at, t0[a : a + k], t1[a : a + k], piece[a : a + k] - offset, own, peak
            )
        )
        first += n
        offset += len(paths[j].coef)
    return out


def _absolute(bound: np.ndarray, peak: np.ndarray) -> tuple[np.ndarray, tuple]:
    """A curve's bounds (3, J, N) plus ROUNDING times its largest bound per order and joint (3, J),
    and those peaks with it: where the curve nearly vanishes (a joint turning: terms of the peak's
    size cancelling), the rounding of the curve and of the bound is absolute, a few 1e-16 of the
    terms (measured: 9e-15 rad/s^2 past a bound of 5e-7, 1.7e-8 of it), which no relative slack
    covers. The same operations for a curve alone and in a batch."""
    slack = ROUNDING * peak
    return bound + slack[:, :, None], tuple(peak + slack)
