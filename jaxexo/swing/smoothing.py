"""B-spline smoothing of generated heel paths (thesis 2.7, Algorithm 5), in metres, vectorised: the
thesis's splprep fit as a penalised B-spline solved in closed form, with the bound on the curve's
distance from the polyline through its samples. Method: docs/generation.md (the fit and the
correction).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

DEFAULT_SMOOTHING = 0.005  # m^2: the thesis's s = 0.5 in decimetres
DEFAULT_POINTS = 100
DEGREE = 3
END_WEIGHT = 1000.0
LOG_LAMBDA = (-12.0, 12.0)  # search range of log10(lambda)
GRID_POINTS = 13
NEWTON_STEPS = 4


def distinct(raw: np.ndarray) -> np.ndarray:
    """The points with consecutive repeats (moves clipped to nothing) removed."""
    raw = np.asarray(raw, dtype=np.float64)
    if len(raw) < 2:
        return raw
    keep = np.ones(len(raw), bool)
    keep[1:] = np.any(np.abs(np.diff(raw, axis=0)) > 1e-9, axis=1)
    return raw[keep]


def linear_resample(raw: np.ndarray, n_points: int = DEFAULT_POINTS, with_deviation: bool = False):
    """The polyline through the raw points, sampled at n points (n, 2); with ``with_deviation`` also
    the largest distance (m) of the raw polyline from the polyline through the samples.

    When the raw path has at most n distinct points, every raw vertex is a sample and the other
    samples divide each segment evenly, in proportion to its length: the polyline through the samples
    is the raw polyline itself (deviation 0, so its checks lose nothing to a bound). Longer paths are
    sampled at n equally spaced arc lengths, where a corner skipped between two samples is cut by
    their chord (the deviation bounds it)."""
    pts = distinct(raw)
    if len(pts) == 1:
        out = np.repeat(pts, n_points, axis=0)
        return (out, 0.0) if with_deviation else out
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if len(pts) <= n_points:
        # n - m extra samples over the m - 1 segments by length (largest remainders), then each segment
        # i contributes its start vertex and k_i evenly spaced interior points; the last vertex closes.
        extra = n_points - len(pts)
        share = seg / s[-1] * extra
        k = np.floor(share).astype(np.int64)
        k[np.argsort(k - share, kind="stable")[: extra - int(k.sum())]] += 1
        idx = np.repeat(np.arange(len(seg)), k + 1)
        j = np.arange(len(idx)) - np.repeat(np.cumsum(k + 1) - (k + 1), k + 1)
        frac = (j / (k[idx] + 1.0))[:, None]
        out = np.vstack([pts[idx] + frac * (pts[idx + 1] - pts[idx]), pts[-1:]])
        return (out, 0.0) if with_deviation else out
    u = np.linspace(0.0, s[-1], n_points)
    out = np.column_stack([np.interp(u, s, pts[:, 0]), np.interp(u, s, pts[:, 1])])
    if not with_deviation:
        return out
    # Each raw vertex against the chord of the two samples around it: the raw piece between two
    # samples is a chain of segments, and a point's distance to a segment is convex along a segment,
    # so the piece's largest distance from its chord is at one of its vertices.
    i = np.clip(np.searchsorted(u, s, side="right") - 1, 0, n_points - 2)
    a, b = out[i], out[i + 1]
    e = b - a
    len2 = np.sum(e * e, axis=-1)
    t = np.clip(np.sum((pts - a) * e, axis=-1) / np.where(len2 > 0, len2, 1.0), 0.0, 1.0)
    return out, float(np.max(np.linalg.norm(pts - a - t[:, None] * e, axis=-1)))


def bspline_design(u: np.ndarray, knots: np.ndarray, k: int) -> np.ndarray:
    """B-spline basis functions of degree k on ``knots`` at parameters u: (len(u), len(knots) - k - 1)
    (Cox-de Boor recursion; the last knot interval is closed so that u = 1 belongs to it). NumPy
    only: importing scipy.interpolate would cost the generator most of its import-time budget."""
    u = np.asarray(u, dtype=np.float64)
    t = np.asarray(knots, dtype=np.float64)
    n_int = len(t) - 1
    last = np.max(np.flatnonzero(t[1:] > t[:-1]))  # the last non-empty interval
    b = ((u[:, None] >= t[None, :-1]) & (u[:, None] < t[None, 1:])).astype(np.float64)
    b[u >= t[last + 1], :] = 0.0
    b[u >= t[last + 1], last] = 1.0
    for d in range(1, k + 1):
        left_den = t[d:n_int] - t[: n_int - d]
        right_den = t[d + 1 : n_int + 1] - t[1 : n_int - d + 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            left = np.where(left_den > 0, (u[:, None] - t[None, : n_int - d]) / left_den, 0.0)
            right = np.where(
                right_den > 0, (t[None, d + 1 : n_int + 1] - u[:, None]) / right_den, 0.0
            )
        b = left * b[:, :-1] + right * b[:, 1:]
    return b


def _generalized_eigh(p: np.ndarray, a: np.ndarray):
    """d, v with p v = d a v, v' a v = I (a symmetric positive definite), via a's Cholesky factor."""
    lower = np.linalg.cholesky(a)
    inv = np.linalg.inv(lower)
    d, w = np.linalg.eigh(inv @ p @ inv.T)
    return d, inv.T @ w


@lru_cache(maxsize=512)
def spline_operators(m: int, n_points: int):
    """For M points: Z (M, M) mapping the points to eigen-coordinates z, the eigenvalues d (M,), and
    E (n_points, M) mapping shrunk eigen-coordinates to the sampled curve."""
    k = DEGREE
    interior = np.linspace(0.0, 1.0, m - k + 1)
    t = np.concatenate([[0.0] * k, interior, [1.0] * k])
    u = np.linspace(0.0, 1.0, m)
    b = bspline_design(u, t, k)  # (M, M)
    w = np.ones(m)
    w[0] = w[-1] = END_WEIGHT**2
    a = b.T @ (w[:, None] * b)
    diff = np.diff(np.eye(m), n=2, axis=0)
    p = diff.T @ diff
    d, v = _generalized_eigh(p, a)  # v' a v = I, v' p v = diag(d)
    d = np.maximum(d, 0.0)
    z = v.T @ (b.T * w[None, :])
    e = bspline_design(np.linspace(0.0, 1.0, n_points), t, k) @ v
    # Coefficients of c'' (a degree-1 B-spline) from c's: differentiate twice (de Boor),
    # P'_j = 3 (P_j+1 - P_j) / (t_j+4 - t_j+1), P''_j = 2 (P'_j+1 - P'_j) / (t_j+4 - t_j+2).
    d1 = 3.0 * np.diff(np.eye(m), axis=0) / (t[4 : m + 3] - t[1:m])[:, None]
    d2 = 2.0 * np.diff(d1, axis=0) / (t[4 : m + 2] - t[2:m])[:, None]
    q = d2 @ v
    for x in (z, d, e, q):
        x.setflags(write=False)
    return z, d, e, q


_GRID = np.linspace(*LOG_LAMBDA, GRID_POINTS)  # log10(lambda) of the bracketing grid
_GRID_LAMBDA = 10.0**_GRID
_TWO_LN10 = 2.0 * np.log(10.0)
for _a in (_GRID, _GRID_LAMBDA):
    _a.setflags(write=False)


def solve_lambda(d: np.ndarray, zz: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Per row: lambda with r(lambda) = sum_j (lambda d_j / (1 + lambda d_j))^2 zz_j = s. r grows
    monotonically in lambda, so a coarse grid brackets the root and Newton steps in log(lambda),
    kept inside the bracket, refine it. inf when even r(inf) stays within s."""
    grid = _GRID
    ld = _GRID_LAMBDA[None, :, None] * d[:, None, :]
    q = ld / (1.0 + ld)
    r = np.einsum("bgm,bm->bg", q * q, zz)  # (B, G), increasing in g
    k = np.clip((r <= s[:, None]).sum(axis=1), 1, GRID_POINTS - 1)  # r[k-1] <= s < r[k]
    rows = np.arange(len(d))
    lo, hi = grid[k - 1], grid[k]
    log_lo, log_hi = (
        np.log(np.maximum(r[rows, k - 1], 1e-300)),
        np.log(np.maximum(r[rows, k], 1e-300)),
    )
    # Start from the interpolation in log(r), then Newton on x = log10(lambda):
    # dr/dx = ln(10) * lambda * dr/dlambda = ln(10) * sum_j 2 q_j^2 (1 - q_j) zz_j.
    # (np.minimum/np.maximum rather than np.clip: the same values, without np.clip's Python wrapper)
    x = lo + (hi - lo) * np.minimum(
        np.maximum(
            (np.log(np.maximum(s, 1e-300)) - log_lo) / np.maximum(log_hi - log_lo, 1e-12), 0
        ),
        1,
    )
    for _ in range(NEWTON_STEPS):
        ld = 10.0 ** x[:, None] * d
        q = ld / (1.0 + ld)
        q2zz = q * q * zz
        rx = q2zz.sum(axis=1)
        drx = _TWO_LN10 * np.einsum("bm,bm->b", q2zz, 1.0 - q)
        x = np.minimum(np.maximum(x - (rx - s) / np.maximum(drx, 1e-300), lo), hi)
    lam = np.where(r[:, -1] <= s, np.inf, 10.0**x)
    return np.where(r[:, 0] > s, 10.0 ** LOG_LAMBDA[0], lam)


def _apply(mat: np.ndarray, x: np.ndarray) -> np.ndarray:
    """mat (R, M) applied to every path of x (G, M, 2) in one matrix product: (G, R, 2)."""
    g, m, _ = x.shape
    y = mat @ x.transpose(1, 0, 2).reshape(m, 2 * g)
    return y.reshape(len(mat), g, 2).transpose(1, 0, 2)


def smooth_paths(
    raws,
    n_points: int = DEFAULT_POINTS,
    smoothing: float | np.ndarray = DEFAULT_SMOOTHING,
    with_deviation: bool = False,
):
    """Smoothed heel paths (B, n_points, 2) for a list of raw agent paths (M_i, 2), metres;
    ``smoothing`` one value or one per path (m^2). ``with_deviation``: also (B,) bounds (m) on the
    curve's distance from the polyline through its samples (docs/safety.md)."""
    lengths = np.array([len(r) for r in raws])
    pts = np.zeros((len(raws), lengths.max(), 2))
    for i, r in enumerate(raws):
        pts[i, : len(r)] = r
    return smooth_padded(pts, lengths, n_points, smoothing, with_deviation)


def smooth_padded(
    pts: np.ndarray,
    lengths: np.ndarray,
    n_points: int = DEFAULT_POINTS,
    smoothing: float | np.ndarray = DEFAULT_SMOOTHING,
    with_deviation: bool = False,
):
    """``smooth_paths`` for paths given as one padded array (B, T, 2) and their lengths (B,)."""
    b, t = pts.shape[:2]
    s_all = np.broadcast_to(np.asarray(smoothing, np.float64), (b,))
    # Drop repeated points (stable compaction of each row), as ``distinct`` does.
    keep = np.arange(t)[None, :] < lengths[:, None]
    keep[:, 1:] &= np.any(np.abs(np.diff(pts, axis=1)) > 1e-9, axis=-1)
    order = np.argsort(~keep, axis=1, kind="stable")
    pts = np.take_along_axis(pts, order[..., None], axis=1)
    m_all = keep.sum(axis=1)
    out = np.empty((b, n_points, 2))
    dev = np.zeros(b)
    for i in np.flatnonzero(m_all < DEGREE + 1):
        out[i], dev[i] = linear_resample(pts[i, : m_all[i]], n_points, with_deviation=True)
    ms = [m for m in np.unique(m_all) if m >= DEGREE + 1]
    if ms:
        mmax = max(ms)
        idxs = [np.flatnonzero(m_all == m) for m in ms]
        z = np.zeros((b, mmax, 2))
        d = np.zeros((b, mmax))
        for m, idx in zip(ms, idxs):
            zm, dm, _, _ = spline_operators(int(m), n_points)
            z[idx, :m] = _apply(zm, pts[idx, :m])
            d[idx, :m] = dm
        smooth = np.concatenate(idxs)
        lam = solve_lambda(d[smooth], np.sum(z[smooth] ** 2, axis=-1), s_all[smooth])
        with np.errstate(invalid="ignore"):
            shrink = np.where(
                np.isinf(lam)[:, None],
                (d[smooth] == 0.0).astype(float),
                1.0 / (1.0 + lam[:, None] * d[smooth]),
            )
        z[smooth] *= shrink[..., None]
        h2_8 = (1.0 / (n_points - 1)) ** 2 / 8.0  # samples at u = i / (n - 1): L^2 / 8
        for m, idx in zip(ms, idxs):
            _, _, em, qm = spline_operators(int(m), n_points)
            out[idx] = _apply(em, z[idx, :m])
            curv = np.max(np.abs(_apply(qm, z[idx, :m])), axis=1)  # (G, 2): max |c''| per axis
            dev[idx] = h2_8 * np.sqrt(np.sum(curv * curv, axis=-1))
    np.maximum(out[..., 1], 0.0, out=out[..., 1])
    out[:, 0] = pts[:, 0]
    out[:, -1] = pts[np.arange(b), m_all - 1]
    return (out, dev) if with_deviation else out


def bspline_smooth(
    raw: np.ndarray, n_points: int = DEFAULT_POINTS, smoothing: float = DEFAULT_SMOOTHING
) -> np.ndarray:
    """One smoothed heel path (n_points, 2): ``smooth_paths`` for a single raw path."""
    return smooth_paths([raw], n_points, smoothing)[0]


def smooth_candidates(raw: np.ndarray, n_points: int, smoothings) -> tuple[np.ndarray, np.ndarray]:
    """One raw path smoothed with each of K smoothings (m^2): ((K, n_points, 2), (K,) deviation
    bounds), as ``smooth_paths([raw] * K, n_points, smoothings, with_deviation=True)`` computes them
    (the same operators and lambda search), with the path's eigen-coordinates computed once and the K
    curves in one matrix product (the generator's candidate smoothings)."""
    s = np.asarray(smoothings, np.float64).reshape(-1)
    k = len(s)
    pts = distinct(raw)
    m = len(pts)
    if m < DEGREE + 1:
        out, dev = linear_resample(pts, n_points, with_deviation=True)
        return np.repeat(out[None], k, axis=0), np.full(k, dev, dtype=np.float64)
    zm, dm, em, qm = spline_operators(m, n_points)
    z = zm @ pts  # (M, 2)
    zz = np.sum(z * z, axis=-1)
    lam = solve_lambda(np.broadcast_to(dm, (k, m)), np.broadcast_to(zz, (k, m)), s)
    with np.errstate(invalid="ignore"):
        shrink = np.where(
            np.isinf(lam)[:, None], (dm == 0.0).astype(float)[None], 1.0 / (1.0 + lam[:, None] * dm)
        )
    zk = z[None] * shrink[..., None]  # (K, M, 2)
    out = np.matmul(em, zk)  # (K, n, 2)
    curv = np.max(np.abs(np.matmul(qm, zk)), axis=1)  # (K, 2)
    dev = (1.0 / (n_points - 1)) ** 2 / 8.0 * np.sqrt(np.sum(curv * curv, axis=-1))
    np.maximum(out[..., 1], 0.0, out=out[..., 1])
    out[:, 0] = pts[0]
    out[:, -1] = pts[-1]
    return out, dev
