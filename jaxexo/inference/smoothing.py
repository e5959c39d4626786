"""B-spline smoothing of generated heel paths (thesis 2.7, Algorithm 5), in metres, vectorised.

The thesis fits ``splprep(points, k=3, s=0.5)`` and samples 100 equally spaced parameter values:
a parametric cubic B-spline, as smooth as possible while the sum of squared residuals at the
agent's points stays within s. Its coordinates were decimetres, so its s = 0.5 dm^2 is
``DEFAULT_SMOOTHING = 0.005`` m^2 here. This module keeps that meaning of s and makes the fit a
few matrix products, so that a batch of paths is smoothed at once:

- Parameter: u_i = i / (M - 1) over the M agent points. Every agent move has the same length
  (step_size), so this is splprep's chord-length parameter, except after a move clipped at the
  ground; repeated points are dropped first.
- Spline: cubic, clamped, M uniformly spaced basis functions (one per point, so s = 0 interpolates),
  fitted by penalised least squares with the P-spline roughness penalty (squared second differences
  of the coefficients). The penalty weight lambda is solved per path so that the residual sum
  equals s; splprep reaches s by adapting its knots instead, so the curves differ slightly, the
  constraint is the same. When even a straight-line fit stays within s, it is used.
- Ends: the swing must leave and land where the agent did, so the first and last points weigh
  END_WEIGHT in the fit and are then set exactly. The heel cannot go below the ground: spline
  overshoot near lift-off and touch-down is clipped to z = 0 (a foot resting on the floor).
- Paths of fewer than four distinct points are resampled as polylines.

Per M, the generalised eigenbasis of (penalty, B'WB) is computed once (Demmler-Reinsch): in it the
residual is sum_j (lambda d_j / (1 + lambda d_j))^2 |z_j|^2, so solving for lambda is a scalar
root search per path, vectorised over the batch.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import BSpline
from scipy.linalg import eigh

DEFAULT_SMOOTHING = 0.005      # m^2: the thesis's s = 0.5 in decimetres
DEFAULT_POINTS = 100
DEGREE = 3
END_WEIGHT = 1000.0
LOG_LAMBDA = (-12.0, 12.0)     # search range of log10(lambda)
GRID_POINTS = 13
NEWTON_STEPS = 6


def distinct(raw: np.ndarray) -> np.ndarray:
    """The points with consecutive repeats (moves clipped to nothing) removed."""
    raw = np.asarray(raw, dtype=np.float64)
    if len(raw) < 2:
        return raw
    keep = np.ones(len(raw), bool)
    keep[1:] = np.any(np.abs(np.diff(raw, axis=0)) > 1e-9, axis=1)
    return raw[keep]


def linear_resample(raw: np.ndarray, n_points: int = DEFAULT_POINTS) -> np.ndarray:
    """The polyline through the raw points, sampled at n equally spaced arc lengths (n, 2)."""
    pts = distinct(raw)
    if len(pts) == 1:
        return np.repeat(pts, n_points, axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    u = np.linspace(0.0, s[-1], n_points)
    return np.column_stack([np.interp(u, s, pts[:, 0]), np.interp(u, s, pts[:, 1])])


@lru_cache(maxsize=512)
def _basis(m: int, n_points: int):
    """For M points: Z (M, M) mapping the points to eigen-coordinates z, the eigenvalues d (M,), and
    E (n_points, M) mapping shrunk eigen-coordinates to the sampled curve."""
    k = DEGREE
    interior = np.linspace(0.0, 1.0, m - k + 1)
    t = np.concatenate([[0.0] * k, interior, [1.0] * k])
    u = np.linspace(0.0, 1.0, m)
    b = BSpline.design_matrix(u, t, k).toarray()                     # (M, M)
    w = np.ones(m)
    w[0] = w[-1] = END_WEIGHT ** 2
    a = b.T @ (w[:, None] * b)
    diff = np.diff(np.eye(m), n=2, axis=0)
    p = diff.T @ diff
    d, v = eigh(p, a)                                                # v' a v = I, v' p v = diag(d)
    d = np.maximum(d, 0.0)
    z = v.T @ (b.T * w[None, :])
    e = BSpline.design_matrix(np.linspace(0.0, 1.0, n_points), t, k).toarray() @ v
    for x in (z, d, e):
        x.setflags(write=False)
    return z, d, e


def _solve_lambda(d: np.ndarray, zz: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Per row: lambda with r(lambda) = sum_j (lambda d_j / (1 + lambda d_j))^2 zz_j = s. r grows
    monotonically in lambda, so a coarse grid brackets the root and Newton steps in log(lambda),
    kept inside the bracket, refine it. inf when even r(inf) stays within s."""
    grid = np.linspace(*LOG_LAMBDA, GRID_POINTS)
    ld = 10.0 ** grid[None, :, None] * d[:, None, :]
    r = np.sum((ld / (1.0 + ld)) ** 2 * zz[:, None, :], axis=2)          # (B, G), increasing
    k = np.clip(np.sum(r <= s[:, None], axis=1), 1, GRID_POINTS - 1)     # r[k-1] <= s < r[k]
    rows = np.arange(len(d))
    lo, hi = grid[k - 1], grid[k]
    r_lo, r_hi = r[rows, k - 1], r[rows, k]
    # Start from the interpolation in log(r), then Newton on x = log10(lambda).
    x = lo + (hi - lo) * np.clip((np.log(np.maximum(s, 1e-300)) - np.log(np.maximum(r_lo, 1e-300))) /
                                 np.maximum(np.log(np.maximum(r_hi, 1e-300)) - np.log(np.maximum(r_lo, 1e-300)), 1e-12), 0, 1)
    for _ in range(NEWTON_STEPS):
        lam = 10.0 ** x[:, None]
        q = lam * d / (1.0 + lam * d)
        rx = np.sum(q * q * zz, axis=1)
        # dr/dx = ln(10) * lambda * dr/dlambda, dq/dlambda = d / (1 + lambda d)^2
        drx = np.log(10.0) * np.sum(2.0 * q * q * (1.0 - q) * zz, axis=1)
        x = np.clip(x - (rx - s) / np.maximum(drx, 1e-300), lo, hi)
    lam = 10.0 ** x
    lam = np.where(r[:, -1] <= s, np.inf, lam)
    return np.where(r[:, 0] > s, 10.0 ** LOG_LAMBDA[0], lam)


def _apply(mat: np.ndarray, x: np.ndarray) -> np.ndarray:
    """mat (R, M) applied to every path of x (G, M, 2) in one matrix product: (G, R, 2)."""
    g, m, _ = x.shape
    y = mat @ x.transpose(1, 0, 2).reshape(m, 2 * g)
    return y.reshape(len(mat), g, 2).transpose(1, 0, 2)


def smooth_paths(raws, n_points: int = DEFAULT_POINTS, smoothing: float | np.ndarray = DEFAULT_SMOOTHING) -> np.ndarray:
    """Smoothed heel paths (B, n_points, 2) for a list of raw agent paths (M_i, 2), metres;
    ``smoothing`` one value or one per path (m^2)."""
    lengths = np.array([len(r) for r in raws])
    pts = np.zeros((len(raws), lengths.max(), 2))
    for i, r in enumerate(raws):
        pts[i, : len(r)] = r
    return smooth_padded(pts, lengths, n_points, smoothing)


def smooth_padded(pts: np.ndarray, lengths: np.ndarray, n_points: int = DEFAULT_POINTS,
                  smoothing: float | np.ndarray = DEFAULT_SMOOTHING) -> np.ndarray:
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
    for i in np.flatnonzero(m_all < DEGREE + 1):
        out[i] = linear_resample(pts[i, : m_all[i]], n_points)
    ms = [m for m in np.unique(m_all) if m >= DEGREE + 1]
    if ms:
        mmax = max(ms)
        idxs = [np.flatnonzero(m_all == m) for m in ms]
        z = np.zeros((b, mmax, 2))
        d = np.zeros((b, mmax))
        for m, idx in zip(ms, idxs):
            zm, dm, _ = _basis(int(m), n_points)
            z[idx, :m] = _apply(zm, pts[idx, :m])
            d[idx, :m] = dm
        smooth = np.concatenate(idxs)
        lam = _solve_lambda(d[smooth], np.sum(z[smooth] ** 2, axis=-1), s_all[smooth])
        with np.errstate(invalid="ignore"):
            shrink = np.where(np.isinf(lam)[:, None], (d[smooth] == 0.0).astype(float),
                              1.0 / (1.0 + lam[:, None] * d[smooth]))
        z[smooth] *= shrink[..., None]
        for m, idx in zip(ms, idxs):
            out[idx] = _apply(_basis(int(m), n_points)[2], z[idx, :m])
    np.maximum(out[..., 1], 0.0, out=out[..., 1])
    out[:, 0] = pts[:, 0]
    out[:, -1] = pts[np.arange(b), m_all - 1]
    return out


def bspline_smooth(raw: np.ndarray, n_points: int = DEFAULT_POINTS, smoothing: float = DEFAULT_SMOOTHING) -> np.ndarray:
    """One smoothed heel path (n_points, 2): ``smooth_paths`` for a single raw path."""
    return smooth_paths([raw], n_points, smoothing)[0]
