"""The timed swing as a curve (NumPy only): the joint path q(s), a C2 cubic spline in arc length,
the time law s(t), a C2 piecewise cubic with bounded s''', and the heel, toe, hip and knees by forward
kinematics from the pivot foot. Why the joints: docs/device-timing.md, "How the timing is computed".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Leg terms of the swing heel relative to the pivot heel: heel = pivot + sum_i SIGN_i L_i e(phi_i),
# phi = (hip_swing, hip_swing + knee_swing, hip_stance, hip_stance + knee_stance), L = (thigh,
# shin, thigh, shin), e(phi) = (sin phi, -cos phi): the thigh and shank directions of eq 2.49.
_SIGN = np.array([1.0, 1.0, -1.0, -1.0])
GROUND_ROUNDING = 1e-12  # m: the forward kinematics' rounding at the floor (a picometre)

# How a controller evaluates SwingCurve.piecewise() (the JSON's "piecewise"), word for word in the
# export; tests/test_piecewise_export.py is an evaluator written from this text alone.
EVALUATE = (
    "q_j(t) = Q_j(S(t)) for t in [0, duration] (clamp t to it: the legs rest outside). "
    "S: the time law piece i is the last one with breakpoints_s[i] <= t (the last piece also holds "
    "at t = duration), S(t) = sum_k c[i][k] (t - breakpoints_s[i])^k, k = 0..3, S from 0 to 1. "
    "Q_j: joint_path.coefficients[j] (j in joint order: hip_swing, knee_swing, hip_stance, "
    "knee_stance), piece m the last one with breakpoints[m] <= S, "
    "Q_j(S) = sum_k c[j][m][k] (S - breakpoints[m])^k. Both are C2. Rates by the chain rule: "
    "q' = Q' S', q'' = Q'' S'^2 + Q' S'', q''' = Q''' S'^3 + 3 Q'' S' S'' + Q' S''' (rad, s)"
)


# --------------------------------------------------------------------------------------------
# The joint path q(s)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class JointPath:
    """q(s) for the four joints: on [knots[i], knots[i+1]], q = c0 + c1 d + c2 d^2 + c3 d^3 with
    d = s - knots[i]; knots (P + 1,) from 0 to 1, coef (P, 4, J) (c0..c3 per joint)."""

    knots: np.ndarray
    coef: np.ndarray

    def derivatives(self, s: np.ndarray, order: int = 3) -> list[np.ndarray]:
        """q and its s-derivatives up to ``order`` at s (n,): a list of (n, J) arrays."""
        return paths_at([self], [np.asarray(s, np.float64)], order)[0]


def median(x: np.ndarray) -> float:
    """``np.median`` of a 1-D array (the same value: the middle one, or the mean of the middle two),
    by one partition: a tenth of np.median's cost on a swing's few hundred steps."""
    n = len(x)
    k = n // 2
    if n % 2:
        return float(np.partition(x, k)[k])
    p = np.partition(x, (k - 1, k))
    return float((p[k - 1] + p[k]) / 2.0)


def unwrapped(q: np.ndarray) -> np.ndarray:
    """``np.unwrap(q, axis=0)`` of joint angles (N, J); q itself where no step reaches pi (the
    joints' usual case: unwrap would only add zeros)."""
    if len(q) < 2 or float(np.abs(np.diff(q, axis=0)).max()) < np.pi:
        return q
    return np.unwrap(q, axis=0)


def chord_knots(q: np.ndarray) -> np.ndarray:
    """Joint-space chord-length fractions (N,) of joint samples (N, J), from 0 to 1 (the samples
    must move: see ``distinct_samples``)."""
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
    return length / length[-1]


def distinct_samples(q: np.ndarray, short: float = 0.25) -> np.ndarray:
    """Indices of the samples (N, J) the spline goes through: a sample closer to the next kept one
    than ``short`` of the median step, or than 1e-4 of the whole path, is dropped (a cubic through
    a chord much shorter than its neighbours swings wide of it), the first and the last sample always kept. Raises ValueError when
    the joints do not move at all."""
    step = np.linalg.norm(np.diff(q, axis=0), axis=1)
    if not float(step.sum()) > 0.0:
        raise ValueError("trajectory: the joints do not move along this path; nothing to time")
    # Relative to the path's length too: a path that mostly stands still has a median step of
    # rounding noise, and knots that close would make the spline's derivatives explode.
    tiny = max(short * median(step[step > 0]), 1e-4 * float(step.sum()))
    keep = np.ones(len(q), bool)
    keep[1:-1] = step[1:] >= tiny  # a sample nearly on the next one goes
    if len(q) > 2 and step[-1] < tiny:  # the landing stays; the sample it nearly repeats goes
        keep[-2] = False
    return np.flatnonzero(keep)


# The trajectory samples a joint path is made from at most: a denser path is timed as if generated
# with this many points. The heel comes as float32 samples (rounding up to 6e-8 m), and a cubic
# through samples h apart amplifies that rounding in its third derivative by 1/h^3: at 5,000 path
# samples the jerk the timing saw was the rounding's and the swing was slowed for it (2.9 s where
# 100 samples took 1.1 s), and past 10,000 every step was below ``distinct_samples``' 1e-4 of the
# path (all dropped but the ends: a straight joint line through the obstacle). With 500, CFFTG's
# and the RL generator's swings at 5,000 and 20,000 points take the time the 100-point ones take
# and pass the checks where their paths do (1,000: up to 1.3x longer).
MAX_PATH_SAMPLES = 500


def thinned(n: int, most: int = MAX_PATH_SAMPLES) -> np.ndarray:
    """Indices of ``n`` samples of a path at most ``most`` + 1 of them, evenly spread over the
    samples (the path as if generated with that many points), the first and the last kept."""
    if n - 1 <= most:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0.0, n - 1, most + 1)).astype(np.int64))


def cubic_paths(knots: np.ndarray, q: np.ndarray) -> list[JointPath]:
    """C2 cubic splines through joint samples q (B, N, J) at knots (B, N), not-a-knot ends (the
    third derivative continuous across the second and the second-last knots), so that a path with
    a cubic shape is reproduced. The slopes solve one tridiagonal system per path."""
    b, n, _ = q.shape
    coef = _spline_coefficients(knots, q, np.full(b, n - 1))
    return [JointPath(knots[i].copy(), coef[i]) for i in range(b)]


def cubic_paths_ragged(knots: list, q: list) -> list[JointPath]:
    """``cubic_paths`` of paths with different sample counts (each (N_b,) and (N_b, J), N_b >= 4),
    in one solve: each system padded to the longest with rows x = 0 that no real row reaches (its
    last row's upper term is 0), so that every path's slopes are the very numbers its own solve
    gives (the same operations on the same values; the padding adds and subtracts exact zeros)."""
    sizes = np.array([len(k) for k in knots])
    b, n, nj = len(knots), int(sizes.max()), q[0].shape[1]
    kk, qq = np.empty((b, n)), np.empty((b, n, nj))
    for j, (k, v) in enumerate(zip(knots, q)):
        m = len(k)
        kk[j, :m], qq[j, :m] = k, v
        kk[j, m:] = k[-1] + np.arange(1, n - m + 1)  # unit steps past the end (no division by 0)
        qq[j, m:] = v[-1]
    coef = _spline_coefficients(kk, qq, sizes - 1)
    return [JointPath(np.array(knots[j], np.float64), coef[j, : sizes[j] - 1]) for j in range(b)]


def _spline_coefficients(knots: np.ndarray, q: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """The pieces' coefficients (B, N-1, 4, J) of the not-a-knot splines through q (B, N, J) at
    knots (B, N) whose last sample is row ``ends`` (B,) (the rows past it padding: x = 0 there)."""
    b, n, nj = q.shape
    h = np.diff(knots, axis=1)  # (B, N-1)
    delta = np.diff(q, axis=1) / h[..., None]  # (B, N-1, J)
    if n < 4:  # a line or a parabola through the samples: one piece per interval, exact
        m = _low_order_slopes(knots, q, delta)
    else:
        lower, diag, upper = np.zeros((b, n)), np.ones((b, n)), np.zeros((b, n))
        rhs = np.zeros((b, n, nj))
        lower[:, 1:-1], diag[:, 1:-1] = h[:, 1:], 2.0 * (h[:, :-1] + h[:, 1:])
        upper[:, 1:-1] = h[:, :-1]
        rhs[:, 1:-1] = 3.0 * (h[:, 1:, None] * delta[:, :-1] + h[:, :-1, None] * delta[:, 1:])
        # Not-a-knot: (m0 + m1 - 2 D0) / h0^2 = (m1 + m2 - 2 D1) / h1^2, with m2 eliminated by the
        # next row; its mirror at the end with m[e-2] eliminated. Both rows become two-term.
        w0, w1 = 1.0 / h[:, 0] ** 2, 1.0 / h[:, 1] ** 2
        f = w1 / h[:, 0]
        diag[:, 0] = w0 + f * h[:, 1]
        upper[:, 0] = w0 - w1 + f * 2.0 * (h[:, 0] + h[:, 1])
        rhs[:, 0] = 2.0 * (w0[:, None] * delta[:, 0] - w1[:, None] * delta[:, 1])
        rhs[:, 0] += f[:, None] * rhs[:, 1]
        rows, e = np.arange(b), ends
        ha, hb = h[rows, e - 2], h[rows, e - 1]
        wa, wb = 1.0 / ha**2, 1.0 / hb**2
        g = wa / hb
        end = 2.0 * (wa[:, None] * delta[rows, e - 2] - wb[:, None] * delta[rows, e - 1])
        end -= g[:, None] * rhs[rows, e - 1]
        pad = np.arange(n)[None, :] > e[:, None]
        lower[pad], diag[pad], upper[pad], rhs[pad] = 0.0, 1.0, 0.0, 0.0
        lower[rows, e], diag[rows, e] = wa - wb - g * 2.0 * (ha + hb), -wb - g * ha
        upper[rows, e] = 0.0
        rhs[rows, e] = end
        m = tridiagonal_solve(lower, diag, upper, rhs)
    hh = h[..., None]
    c2 = (3.0 * delta - 2.0 * m[:, :-1] - m[:, 1:]) / hh
    c3 = (m[:, :-1] + m[:, 1:] - 2.0 * delta) / (hh * hh)
    return np.stack([q[:, :-1], m[:, :-1], c2, c3], axis=2)  # (B, N-1, 4, J)


def tridiagonal_solve(lower, diag, upper, rhs) -> np.ndarray:
    """x with lower[i] x[i-1] + diag[i] x[i] + upper[i] x[i+1] = rhs[i] (Thomas algorithm), for
    systems (B, N) with right-hand sides (B, N, J). A few systems run as Python floats (a row costs
    less than a NumPy call), many as one vectorised sweep."""
    b, n, nj = rhs.shape
    if b <= 4:
        return np.stack([_thomas_floats(lower[i], diag[i], upper[i], rhs[i]) for i in range(b)])
    cp = np.empty((b, n))
    dp = np.empty((b, n, nj))
    cp[:, 0] = upper[:, 0] / diag[:, 0]
    dp[:, 0] = rhs[:, 0] / diag[:, 0, None]
    for i in range(1, n):
        den = diag[:, i] - lower[:, i] * cp[:, i - 1]
        cp[:, i] = upper[:, i] / den
        dp[:, i] = (rhs[:, i] - lower[:, i, None] * dp[:, i - 1]) / den[:, None]
    x = np.empty((b, n, nj))
    x[:, -1] = dp[:, -1]
    for i in range(n - 2, -1, -1):
        x[:, i] = dp[:, i] - cp[:, i, None] * x[:, i + 1]
    return x


def _thomas_floats(lower, diag, upper, rhs) -> np.ndarray:
    lo, di, up = lower.tolist(), diag.tolist(), upper.tolist()
    d = rhs.tolist()
    n, nj = rhs.shape
    if nj == 4:
        return _thomas_floats4(lo, di, up, d)
    cp = [up[0] / di[0]] + [0.0] * (n - 1)
    dp = [[v / di[0] for v in d[0]]] + [None] * (n - 1)
    for i in range(1, n):
        li = lo[i]
        den = di[i] - li * cp[i - 1]
        cp[i] = up[i] / den
        prev = dp[i - 1]
        dp[i] = [(d[i][j] - li * prev[j]) / den for j in range(nj)]
    x = [None] * n
    x[-1] = dp[-1]
    for i in range(n - 2, -1, -1):
        c, nxt = cp[i], x[i + 1]
        x[i] = [dp[i][j] - c * nxt[j] for j in range(nj)]
    return np.array(x)


def _thomas_floats4(lo, di, up, d) -> np.ndarray:
    """``_thomas_floats`` for four right-hand sides (the joints), unrolled: the same operations in
    the same order, without a comprehension per row."""
    n = len(di)
    cp = [up[0] / di[0]] + [0.0] * (n - 1)
    d0 = di[0]
    r = d[0]
    p0, p1, p2, p3 = r[0] / d0, r[1] / d0, r[2] / d0, r[3] / d0
    dp = [(p0, p1, p2, p3)] + [None] * (n - 1)
    for i in range(1, n):
        li = lo[i]
        den = di[i] - li * cp[i - 1]
        cp[i] = up[i] / den
        r = d[i]
        p0 = (r[0] - li * p0) / den
        p1 = (r[1] - li * p1) / den
        p2 = (r[2] - li * p2) / den
        p3 = (r[3] - li * p3) / den
        dp[i] = (p0, p1, p2, p3)
    x = [None] * n
    x[-1] = dp[-1]
    for i in range(n - 2, -1, -1):
        c = cp[i]
        q = dp[i]
        p0, p1, p2, p3 = q[0] - c * p0, q[1] - c * p1, q[2] - c * p2, q[3] - c * p3
        x[i] = (p0, p1, p2, p3)
    return np.array(x)


def _low_order_slopes(knots, q, delta):
    """Slopes (B, N, J) for N = 2 (the line) or N = 3 (the parabola through the three samples)."""
    if q.shape[1] == 2:
        return np.repeat(delta, 2, axis=1)
    x = knots[..., None]
    c = (delta[:, 1] - delta[:, 0]) / (x[:, 2] - x[:, 0])  # the parabola's second coefficient
    m0 = delta[:, 0] - c * (x[:, 1] - x[:, 0])
    return np.stack([m0, m0 + 2.0 * c * (x[:, 1] - x[:, 0]), m0 + 2.0 * c * (x[:, 2] - x[:, 0])], 1)


def pchip_slopes(y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson slopes (per unit sample index) of samples y (N, D): the harmonic mean of the
    neighbouring differences where they share a sign, zero at local extrema, so the interpolant
    never overshoots the samples; shape-preserving three-point ends."""
    d = np.diff(y, axis=0)
    if len(d) == 1:
        return np.repeat(d, 2, axis=0)
    d0, d1 = d[:-1], d[1:]
    same = d0 * d1 > 0
    m = np.zeros_like(y)
    with np.errstate(divide="ignore", invalid="ignore"):
        m[1:-1] = np.where(same, 2.0 * d0 * d1 / np.where(same, d0 + d1, 1.0), 0.0)
    for end, a, b in ((0, d[0], d[1]), (-1, d[-1], d[-2])):
        e = 0.5 * (3.0 * a - b)
        e = np.where(np.sign(e) != np.sign(a), 0.0, e)
        e = np.where((np.sign(a) != np.sign(b)) & (np.abs(e) > 3.0 * np.abs(a)), 3.0 * a, e)
        m[end] = e
    return m


def pchip_eval(y: np.ndarray, m: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolant of samples y (N, D) with slopes m at sample coordinates u (K,)
    in [0, N-1]: (K, D)."""
    n = y.shape[0]
    u = np.clip(np.asarray(u, np.float64), 0.0, n - 1)
    i = np.minimum(np.floor(u).astype(np.int64), n - 2)
    t = (u - i)[:, None]
    t2, t3 = t * t, t * t * t
    # Rows by np.take: the same values as y[i], at a tenth of a multi-column fancy index's cost.
    y0, y1, m0, m1 = (np.take(a, j, axis=0) for a, j in ((y, i), (y, i + 1), (m, i), (m, i + 1)))
    return (
        (2 * t3 - 3 * t2 + 1) * y0
        + (t3 - 2 * t2 + t) * m0
        + (-2 * t3 + 3 * t2) * y1
        + (t3 - t2) * m1
    )


# --------------------------------------------------------------------------------------------
# Forward kinematics with derivatives
# --------------------------------------------------------------------------------------------


def _phases(q):
    """The absolute segment angles phi (..., 4) of joint values (..., 4), or of their derivatives."""
    return np.stack([q[..., 0], q[..., 0] + q[..., 1], q[..., 2], q[..., 2] + q[..., 3]], axis=-1)


def segments(q: np.ndarray) -> np.ndarray:
    """The unit vectors (n, 4, 2) along the legs' segments (from hip to knee, knee to heel) of joint
    angles (n, 4): (sin phi, -cos phi) of their absolute angles."""
    phi = _phases(q)
    return np.stack([np.sin(phi), -np.cos(phi)], axis=-1)


def heel_derivatives(lengths, pivot_y: float, qs: list[np.ndarray], e=None) -> list[np.ndarray]:
    """The swing heel (n, 2) and its derivatives (same order as ``qs``, up to the third) for joint
    values and derivatives qs = [q, q', q'', q'''] (each (n, 4)): forward kinematics from the pivot
    heel on the ground, heel = pivot + sum_i sign_i L_i e(phi_i), differentiated term by term
    (e' = phi' e_perp, e_perp' = -phi' e); ``e``: ``segments(qs[0])`` when known."""
    thigh, shin = lengths
    ln = _SIGN * np.array([thigh, shin, thigh, shin])
    e = segments(qs[0]) if e is None else e  # (n, 4, 2)
    ep = np.stack([-e[..., 1], e[..., 0]], axis=-1)  # (cos phi, sin phi), exactly
    out = [np.einsum("i,nik->nk", ln, e)]
    out[0][:, 0] += pivot_y  # a number, or one per row
    if len(qs) > 1:
        p1 = _phases(qs[1])[..., None]
        out.append(np.einsum("i,nik->nk", ln, p1 * ep))
    if len(qs) > 2:
        p2 = _phases(qs[2])[..., None]
        out.append(np.einsum("i,nik->nk", ln, p2 * ep - p1 * p1 * e))
    if len(qs) > 3:
        p3 = _phases(qs[3])[..., None]
        out.append(np.einsum("i,nik->nk", ln, (p3 - p1**3) * ep - 3.0 * p1 * p2 * e))
    return out


def leg_points(lengths, pivot_y: float, e: np.ndarray) -> tuple[np.ndarray, ...]:
    """Hip, swing knee and stance knee (n, 2) each of the legs' ``segments`` e (n, 4, 2): the
    stance leg from the pivot heel up to the hip, the swing leg down from it."""
    thigh, shin = lengths
    hip = -thigh * e[:, 2] - shin * e[:, 3]
    hip[:, 0] += pivot_y  # a number, or one per row
    return hip, hip + thigh * e[:, 0], hip + thigh * e[:, 2]


# phi = q @ _PHASE: the absolute segment angles (hip, hip + knee of each leg) of joint values (or of
# their derivatives, or of bounds on them: sums of bounds bound the summed angles).
_PHASE = np.array(
    [[1.0, 1.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.0]]
)


def heel_second_derivative_bounds(lengths, h: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Per piece of a joint path (P,), an upper bound on |d2 heel / ds2| (m): the leg terms
    L (phi'' e_perp - phi'^2 e) summed, each of length L sqrt(phi''^2 + phi'^4) (e, e_perp
    orthonormal), with per-piece bounds on the joints' |q'| <= |c1| + 2 |c2| h + 3 |c3| h^2 and
    |q''| <= 2 |c2| + 6 |c3| h (sums of bounds bound the summed angles). ``h`` (P, 1): the pieces'
    lengths; ``coef`` (4, P, J): the path's coefficients c0..c3, each a contiguous block."""
    _, c1, c2, c3 = np.abs(coef)
    c2x2, c3x3h = 2.0 * c2, (3.0 * h) * c3
    mid = c2x2 + c3x3h
    a1 = (c1 + mid * h) @ _PHASE
    a1 *= a1
    a2 = (mid + c3x3h) @ _PHASE
    return np.sqrt(a2 * a2 + a1 * a1) @ _leg_terms(lengths)[1]


def _leg_terms(lengths) -> tuple[np.ndarray, np.ndarray]:
    """The heel's leg terms sign_i L_i (4,) and their lengths |L_i|, per (thigh, shin), kept."""
    key = (float(lengths[0]), float(lengths[1]))
    out = _LEG_TERMS.get(key)
    if out is None:
        ln = np.array([key[0], key[1], key[0], key[1]])
        out = _LEG_TERMS[key] = (_SIGN * ln, np.abs(ln))
    return out


_LEG_TERMS: dict = {}


def check_points(lengths, pivot_y: float, path: JointPath, tol: float):
    """The verdict's polyline on the curve: path parameters s (n,) from 0 to 1, every knot among
    them, spaced so that the heel curve strays at most ``tol`` (m) from the polyline through them
    (on a piece with |h''| <= B, a chord over Delta s deviates by at most Delta s^2 B / 8), with
    the joints q (n, J) and the heel (n, 2) there (heights within GROUND_ROUNDING of the floor on
    it). Each point is evaluated on its own piece at its offset (no search)."""
    knots = path.knots
    h = knots[1:] - knots[:-1]
    ct = np.ascontiguousarray(path.coef.transpose(1, 0, 2))  # (4, P, J): contiguous blocks
    bound = heel_second_derivative_bounds(lengths, h[:, None], ct)
    n = np.maximum(np.ceil(h * np.sqrt(bound * (0.125 / tol))), 1.0).astype(np.int64)
    m = n.copy()
    m[-1] += 1  # the last piece also holds s = 1
    piece = np.repeat(np.arange(len(h)), m)
    j = np.arange(len(piece)) - (np.cumsum(n) - n)[piece]
    d = j * (h / n)[piece]
    d[-1] = h[-1]
    s = knots[piece] + d
    s[-1] = 1.0
    c0, c1, c2, c3 = np.take(ct, piece, axis=1)
    d = d[:, None]
    q = ((c3 * d + c2) * d + c1) * d + c0
    phi = q @ _PHASE
    ln = _leg_terms(lengths)[0]
    heel = np.empty((len(s), 2))
    heel[:, 0] = np.sin(phi) @ ln + pivot_y
    z = -(np.cos(phi) @ ln)
    # The forward kinematics' rounding at the floor (a picometre), not a motion.
    heel[:, 1] = np.where(np.abs(z) < GROUND_ROUNDING, 0.0, z)
    return s, q, heel


# --------------------------------------------------------------------------------------------
# The time law s(t)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TimeLaw:
    """s(t): a piecewise-linear speed v(t) through (nodes, speed), rest at both ends, whose integral
    over [0, nodes[-1]] is 1, averaged over a sliding window w (a box filter):
    s'(t) = (S(t) - S(t - w)) / w with S = integral of v. Then s is a C2 piecewise cubic on
    [0, nodes[-1] + w] with breakpoints at the nodes and the nodes + w, s'' = (v(t) - v(t - w)) / w
    and s''' = (v'(t) - v'(t - w)) / w bounded (Biagiotti & Melchiorri's FIR view of smoothing a
    time-optimal law). All values are exact closed forms of the nodes."""

    nodes: np.ndarray  # (M + 1,) s, from 0
    speed: np.ndarray  # (M + 1,) 1/s, 0 at both ends
    window: float  # s

    def __post_init__(self):
        dt = np.diff(self.nodes)
        acc = np.diff(self.speed) / np.where(dt > 0, dt, 1.0)
        area = 0.5 * (self.speed[:-1] + self.speed[1:]) * dt
        big_s = np.concatenate([[0.0], np.cumsum(area)])
        # P = integral of S: per segment S_i dt + v_i dt^2 / 2 + a_i dt^3 / 6.
        inc = big_s[:-1] * dt + self.speed[:-1] * dt * dt / 2.0 + acc * dt**3 / 6.0
        big_p = np.concatenate([[0.0], np.cumsum(inc)])
        object.__setattr__(self, "_acc", acc)
        object.__setattr__(self, "_S", big_s)
        object.__setattr__(self, "_P", big_p)

    @property
    def duration(self) -> float:
        return float(self.nodes[-1] + self.window)

    def slowed(self, k: float) -> "TimeLaw":
        """s(t / k): velocities / k, accelerations / k^2, jerks / k^3."""
        return TimeLaw(self.nodes * k, self.speed / k, self.window * k)

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """s and its first three time derivatives at times t (n,), clamped to [0, duration]."""
        return laws_at([self], [np.asarray(t, np.float64)])[0]

    def breakpoints(self) -> np.ndarray:
        """Where s''' may jump: the nodes and the nodes + w, sorted, within [0, duration]."""
        b = np.unique(np.concatenate([self.nodes, self.nodes + self.window]))
        return b[b <= self.duration]

    def pieces(self) -> tuple[np.ndarray, np.ndarray]:
        """The piecewise-cubic form: breakpoints (P + 1,) and coefficients (P, 4), s(t) =
        c0 + c1 d + c2 d^2 + c3 d^3 with d = t - breakpoints[i] on piece i."""
        b = self.breakpoints()
        s, s1, s2, _ = self.at(b[:-1])  # continuous (C2): the piece's own values at its start
        # s''' jumps at a breakpoint, so it is read inside the piece, never at its start: a start
        # of the form node + w can round just below the node, where the left neighbour's jerk
        # holds (that once put 1.5 % of the exported pieces on the wrong jerk).
        s3 = self.at(0.5 * (b[:-1] + b[1:]))[3]
        return b, np.stack([s, s1, s2 / 2.0, s3 / 6.0], axis=1)


def law_from_speeds(
    s_grid: np.ndarray, x: np.ndarray, floor: np.ndarray, window: float, fraction: float = 1.0
) -> TimeLaw:
    """The time law of speeds s'^2 = x (K,) on s_grid (K,), constant s'' per cell (the TOPP passes'
    law), each cell's mean speed at least ``floor`` (K - 1,): a cell where the floor binds is crossed
    at a peak in its middle (two linear pieces) so that it still covers its length. Then averaged
    over ``window`` (s), at most ``fraction`` of the passes' duration."""
    nodes, speed = speed_nodes(s_grid, x, floor)
    t_end = nodes[-1]
    return TimeLaw(nodes, speed, float(min(window, fraction * t_end)) if t_end > 0 else window)


def speed_nodes(
    s_grid: np.ndarray, x: np.ndarray, floor: np.ndarray, start: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """``law_from_speeds``' piecewise-linear speed before its averaging: nodes (M + 1,) s from 0 and
    speeds (M + 1,) 1/s, from ``start`` (1/s: a law that continues a moving one, its speed there
    exactly; 0: rest) to rest at the end."""
    v = np.sqrt(np.maximum(x, 0.0))
    v[0] = start
    ds = np.diff(s_grid)
    mean = np.maximum(0.5 * (v[:-1] + v[1:]), np.maximum(floor, 1e-12))
    dt = ds / mean
    lin = 0.5 * (v[:-1] + v[1:])
    t = np.concatenate([[0.0], np.cumsum(dt)])
    bind = np.flatnonzero(mean > lin * (1.0 + 1e-12))
    # A cell where the floor binds gets a middle node at the speed that makes its area ds.
    nodes = np.insert(t, bind + 1, t[bind] + 0.5 * dt[bind])
    speed = np.insert(v, bind + 1, 2.0 * mean[bind] - lin[bind])
    speed[-1] = 0.0
    return nodes, speed


# --------------------------------------------------------------------------------------------
# Many curves at once: each law and path is stored as itself; an evaluation of many stacks them
# with offsets, so that one searchsorted finds every query's piece (a row of the stacked arrays
# never mixes two swings, and the arithmetic inside a piece is the single curve's own).
# --------------------------------------------------------------------------------------------


def _segments(lengths, counts) -> tuple[np.ndarray, np.ndarray]:
    """Per query, the start of its item's rows and its item's index (both (sum counts,))."""
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    item = np.repeat(np.arange(len(counts)), counts)
    return starts[item], item


def laws_at(laws, times) -> list[tuple]:
    """s, s', s'', s''' of each law at its times: a list of 4-tuples of (n_b,) arrays.

    s(t) = (P(t) - P(t - w)) / w with P the integral of S = integral of v (TimeLaw). At t the
    law is either inside the passes' nodes or past them at rest (S = total, P grows linearly);
    at t - w it is inside them or before the start (all zero)."""
    counts = [len(t) for t in times]
    res = _laws_flat(laws, times, counts)
    if len(laws) == 1:
        return [tuple(res)]
    return list(zip(*(_split(x, counts) for x in res)))


def _laws_flat(laws, times, counts) -> list[np.ndarray]:
    """``laws_at``'s four values of all laws at all their times, concatenated (n,) each."""
    if len(laws) == 1:
        return _law_at(laws[0], times[0])
    counts = np.array(counts)
    lens = np.array([len(law.nodes) for law in laws])
    w = np.array([law.window for law in laws])
    end = np.array([law.nodes[-1] for law in laws])
    off = np.concatenate([[0.0], np.cumsum(end + 1.0)[:-1]])
    cat = np.concatenate
    nodes = cat([law.nodes for law in laws])
    speed = cat([law.speed for law in laws])
    acc = cat([np.append(law._acc, 0.0) for law in laws])
    big_s, big_p = cat([law._S for law in laws]), cat([law._P for law in laws])
    start, item = _segments(lens, counts)
    t_in = cat(list(times))
    t = np.clip(t_in, 0.0, (end + w)[item])
    last = start + lens[item] - 1
    total, end_i, w_i = big_s[last], end[item], w[item]
    keys = nodes + np.repeat(off, lens)

    def piece(local):
        i = np.searchsorted(keys, local + off[item], side="right") - 1
        i = np.minimum(i, last - 1)
        d = local - nodes[i]
        a = acc[i]
        v0 = speed[i]
        return (
            big_p[i] + (big_s[i] + (0.5 * v0 + a * d / 6.0) * d) * d,
            big_s[i] + (v0 + 0.5 * a * d) * d,
            v0 + a * d,
            a,
        )

    return _windowed(piece, t, t_in, end_i, w_i, total)


def _windowed(piece, t, t_in, end, w, total) -> list[np.ndarray]:
    """The law's four values at clamped times t (queries t_in) from ``piece`` (P, S, v and v' of
    the passes' law within it), the law's end (its last node), window w and total S: arrays per
    query for a batch, numbers for one law (the same operations either way)."""
    past = t >= end  # at rest after the passes' last node
    p1, s1, v1, a1 = piece(np.minimum(t, end))
    p1 = p1 + total * np.maximum(t - end, 0.0)
    v1[past] = 0.0
    a1 = np.where(past, 0.0, a1)
    lag = t - w
    p0, s0, v0, a0 = piece(np.maximum(lag, 0.0))  # all zero at the start, but the piece's v'
    a0 = np.where(lag < 0.0, 0.0, a0)
    k = 1.0 / (w * total)
    res = [np.clip((p1 - p0) * k, 0.0, 1.0), (s1 - s0) * k, (v1 - v0) * k, (a1 - a0) * k]
    # At touch-down exactly at rest (t - w rounds to a hair before the last node); before lift-off
    # too (clamped to t = 0, the jerk there is the first piece's, not the rest's).
    landed = t >= end + w
    for x, val in zip(res, (1.0, 0.0, 0.0, 0.0)):
        x[landed] = val
    early = t_in < 0.0
    if early.any():
        for x in res:
            x[early] = 0.0
    return res


def _law_at(law, t_in) -> list[np.ndarray]:
    """``_laws_flat`` of one law: the same arithmetic on scalars where the batch has one value per
    query (a law's window, end and total), without the batch's offsets."""
    nodes, speed, acc, big_s, big_p = law.nodes, law.speed, law._acc, law._S, law._P
    last = len(nodes) - 1
    w, end = law.window, nodes[-1]
    total = big_s[last]
    t = np.clip(t_in, 0.0, end + w)

    def piece(local):
        # rows by np.take (the values of fancy indexing, at less cost); i < last: within acc
        i = np.minimum(np.searchsorted(nodes, local, side="right") - 1, last - 1)
        d = local - np.take(nodes, i)
        a = np.take(acc, i)
        v0 = np.take(speed, i)
        bs = np.take(big_s, i)
        return (
            np.take(big_p, i) + (bs + (0.5 * v0 + a * d / 6.0) * d) * d,
            bs + (v0 + 0.5 * a * d) * d,
            v0 + a * d,
            a,
        )

    return _windowed(piece, t, t_in, end, w, total)


def _split(x: np.ndarray, counts) -> list[np.ndarray]:
    """x cut along its first axis into consecutive parts of ``counts`` rows: views, as np.split
    gives, at a fraction of its cost per call."""
    out, start = [], 0
    for n in counts:
        out.append(x[start : start + n])
        start += n
    return out


def paths_at(paths, params, order: int = 3) -> list[list[np.ndarray]]:
    """q and its s-derivatives up to ``order`` of each path at its parameters: a list of lists of
    (n_b, J) arrays."""
    if len(paths) == 1:
        return [_paths_flat(paths, np.asarray(params[0], np.float64), None, order)]
    counts = [len(s) for s in params]
    res = _paths_flat(paths, np.concatenate(params), counts, order)
    return [list(x) for x in zip(*(_split(r, counts) for r in res))]


def _paths_flat(paths, s: np.ndarray, counts, order: int) -> list[np.ndarray]:
    """``paths_at`` of all paths at all their parameters s (concatenated, ``counts`` each; None
    for one path): q and its derivatives (n, J) each."""
    if len(paths) == 1:
        knots, coef = paths[0].knots[:-1], paths[0].coef
        i = np.maximum(np.searchsorted(knots, s, side="right") - 1, 0)
        i = np.minimum(i, len(coef) - 1)
        d = (s - np.take(knots, i))[:, None]
    else:
        pieces = np.array([len(p.coef) for p in paths])
        knots = np.concatenate([p.knots[:-1] for p in paths])
        keys = knots + np.repeat(2.0 * np.arange(len(paths)), pieces)  # for the search only
        coef = np.concatenate([p.coef for p in paths])
        start, item = _segments(pieces, counts)
        i = np.searchsorted(keys, np.clip(s, 0.0, 1.0) + 2.0 * item, side="right") - 1
        i = np.clip(i, start, start + pieces[item] - 1)
        d = (s - knots[i])[:, None]  # as one path computes it: batch = single, bit for bit
    # Gathered by np.take from the (4, P, J) layout: each coefficient a contiguous (n, J) block
    # (the same values; fancy indexing, or arithmetic on the strided columns of coef[i], cost
    # several times as much).
    c0, c1, c2, c3 = np.take(np.ascontiguousarray(coef.transpose(1, 0, 2)), i, axis=1)
    res = [((c3 * d + c2) * d + c1) * d + c0]
    if order >= 1:
        res.append((3.0 * c3 * d + 2.0 * c2) * d + c1)
    if order >= 2:
        res.append(6.0 * c3 * d + 2.0 * c2)
    if order >= 3:
        res.append(6.0 * c3)
    return res


def joints_at(paths, laws, times, lv=None) -> list[tuple]:
    """For each (path, law) at its times: s (n_b,) and [q, q-dot, q-ddot, q-dddot] (n_b, J) each,
    the chain rule on q(s(t)); ``lv``: ``laws_at(laws, times)`` when known."""
    counts = [len(t) for t in times]
    if lv is None:
        flat = _laws_flat(laws, times, counts)
    elif len(paths) == 1:
        flat = list(lv[0])
    else:
        flat = [np.concatenate(list(x)) for x in zip(*lv)]
    derivs = _chain(paths, flat, counts)
    if len(paths) == 1:
        return [(flat[0], derivs)]
    split = [_split(x, counts) for x in derivs]
    return [(s, [split[o][b] for o in range(4)]) for b, s in enumerate(_split(flat[0], counts))]


def _chain(paths, law_values, counts) -> list[np.ndarray]:
    """q and its three time derivatives (n, J) each, by the chain rule, of all paths at their
    laws' four values (``_laws_flat``) at all their times (concatenated, ``counts`` each)."""
    one = len(paths) == 1
    d0, d1, d2, d3 = _paths_flat(paths, law_values[0], None if one else counts, 3)
    _, s1, s2, s3 = (x[:, None] for x in law_values)
    s1s1 = s1 * s1
    return [d0, d1 * s1, d2 * s1s1 + d1 * s2, (d3 * s1s1 + 3.0 * d2 * s2) * s1 + d1 * s3]


# --------------------------------------------------------------------------------------------
# The curve
# --------------------------------------------------------------------------------------------


BYTES_PER_TIME = 1024  # what ``SwingCurve.at`` holds per time at its peak (measured: 704 B)


def _shown(v) -> str:
    """A value as given, cut short (an array of millions of times is not a message)."""
    r = repr(v)
    return r if len(r) <= 80 else r[:77] + "..."


def checked_times(t, name: str = "t") -> np.ndarray:
    """Times (s) as a 1-D float64 array: a real number, or a 1-D sequence or array of real numbers,
    all finite. TypeError naming ``name`` and the value as given for a string, a bool, None or a
    complex number (NumPy would read "0.4" as 0.4 and True as 1 s); ValueError for NaN, infinities,
    a 2-D array, or more times than half the memory this process may use holds at BYTES_PER_TIME
    (refused before anything is allocated)."""
    what = f"{name}: expected times in s (a real number or a 1-D array of them)"
    if t is None or isinstance(t, (str, bytes, bool, np.bool_, complex, np.complexfloating)):
        raise TypeError(f"{what}, got {_shown(t)}")
    try:
        arr = np.asarray(t)
    except (TypeError, ValueError):  # a ragged or mixed sequence
        raise TypeError(f"{what}, got {_shown(t)}") from None
    if arr.dtype.kind not in "iuf":  # bools, complex, strings, objects (None among numbers)
        raise TypeError(f"{what}, got {_shown(t)}")
    if arr.ndim > 1:
        raise ValueError(f"{what}, got an array of shape {arr.shape}")
    from jaxexo.config.memory import process_memory_bytes

    most = process_memory_bytes() // 2 // BYTES_PER_TIME
    if arr.size > most:
        raise ValueError(
            f"{name}: {arr.size} times need about {arr.size * BYTES_PER_TIME / 2**30:.3g} GiB, more "
            f"than half the memory this process may use holds ({most} times); evaluate them in "
            "chunks"
        )
    arr = np.atleast_1d(arr.astype(np.float64))
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected finite times in s, got {_shown(t)}")
    return arr


@dataclass(frozen=True)
class CurveState:
    """The swing at times (n,): joints (n, 4) rad and their time derivatives (rad/s, rad/s^2,
    rad/s^3), the swing heel (n, 2) m with its velocity, acceleration and jerk (the toe moves with
    it: the foot stays level), the hip and both knees (n, 2) m, and the path parameter s (n,)."""

    time: np.ndarray
    path_parameter: np.ndarray
    joint_angles: np.ndarray
    joint_velocity: np.ndarray
    joint_acceleration: np.ndarray
    joint_jerk: np.ndarray
    heel: np.ndarray
    heel_velocity: np.ndarray
    heel_acceleration: np.ndarray
    heel_jerk: np.ndarray | None  # None where not asked (curves_at)
    toe: np.ndarray
    hip: np.ndarray
    knee_swing: np.ndarray
    knee_stance: np.ndarray


@dataclass(frozen=True)
class SwingCurve:
    """A timed swing as a curve: joints q(s(t)) for t in [0, duration], at rest at both ends."""

    path: JointPath
    law: TimeLaw
    pivot_y: float  # m
    lengths: tuple[float, float]  # thigh, shin (m)
    foot_length: float  # m

    @property
    def duration(self) -> float:
        return self.law.duration

    def joints(self, t) -> tuple[np.ndarray, list[np.ndarray]]:
        """s (n,) and [q, q-dot, q-ddot, q-dddot] (n, 4) each at times t: the chain rule on q(s(t))."""
        return joints_at([self.path], [self.law], [np.asarray(t, np.float64)])[0]

    def at(self, t) -> CurveState:
        """Every joint and the heel/toe, with their derivatives, at times t (s: a real number or a
        1-D array of them, ``checked_times``). Before the swing starts and after it lands the legs
        rest: the end poses, every derivative zero."""
        return curves_at([self], [checked_times(t)])[0]

    def piecewise(self) -> dict:
        """The piecewise-polynomial form for a controller that evaluates the curve itself:
        s(t) and q_j(s), cubic pieces each (module docstring), JSON values."""
        tb, tc = self.law.pieces()
        return {
            "evaluate": EVALUATE,
            "time_law": {"breakpoints_s": tb.tolist(), "coefficients": tc.tolist()},
            "joint_path": {
                "breakpoints": self.path.knots.tolist(),
                "coefficients": self.path.coef.transpose(2, 0, 1).tolist(),
            },
        }


def curves_at(curves, times, heel_jerk: bool = True) -> list[CurveState]:
    """``SwingCurve.at`` of each curve at its times, in one evaluation (the curves share their
    leg lengths and foot); ``heel_jerk=False``: the states' ``heel_jerk`` None (samples do not
    export it, and its cube of the angle rates costs half the forward kinematics)."""
    counts = [len(t) for t in times]
    lv = _laws_flat([c.law for c in curves], times, counts)
    qs = _chain([c.path for c in curves], lv, counts)
    one = len(curves) == 1
    # The pivot: a number for one curve, one per row for many (the same sums).
    pivot = curves[0].pivot_y if one else np.repeat([c.pivot_y for c in curves], counts)
    e = segments(qs[0])  # one forward kinematics for the heel and the leg points
    h = heel_derivatives(curves[0].lengths, pivot, qs if heel_jerk else qs[:3], e)
    h += [None] * (4 - len(h))
    toe = h[0].copy()
    toe[:, 0] += curves[0].foot_length
    legs = leg_points(curves[0].lengths, pivot, e)
    cols = (lv[0], *qs, *h, toe, *legs)
    if one:
        return [CurveState(times[0], *cols)]
    cols = [[None] * len(curves) if x is None else _split(x, counts) for x in cols]
    return [CurveState(t, *(c[b] for c in cols)) for b, t in enumerate(times)]
