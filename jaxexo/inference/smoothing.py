"""B-spline smoothing of a generated heel path (thesis 2.7, Algorithm 5), in metres.

The thesis fits ``splprep(points, k=3, s=0.5)`` and samples it at 100 equally spaced parameter
values. Its coordinates were decimetres, so its s = 0.5 dm^2 (a bound on the sum of squared
residuals) is ``DEFAULT_SMOOTHING = 0.005`` m^2 here. Decisions the thesis leaves open:

- The swing must start and end where the agent did (the heel leaves and lands on the ground), so the
  two end points get a weight of ``END_WEIGHT`` in the fit and are then set exactly.
- The heel cannot go below the ground; spline overshoot near lift-off and touch-down is clipped to
  z = 0 (a foot resting on the floor).
- Repeated points (a move clipped at the world's bounds) are dropped: the parameter is the
  cumulative chord length and must increase. Paths too short for a cubic get a lower degree.
- smoothing = 0 interpolates the agent's points with a cubic; ``linear_resample`` gives the raw
  polyline itself at the same number of samples (the generator's last fallback).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import splev, splprep

DEFAULT_SMOOTHING = 0.005      # m^2: the thesis's s = 0.5 in decimetres
DEFAULT_POINTS = 100
DEGREE = 3
END_WEIGHT = 1000.0


def _distinct(raw: np.ndarray) -> np.ndarray:
    raw = np.asarray(raw, dtype=np.float64)
    if len(raw) < 2:
        return raw
    keep = np.ones(len(raw), bool)
    keep[1:] = np.linalg.norm(np.diff(raw, axis=0), axis=1) > 1e-9
    return raw[keep]


def linear_resample(raw: np.ndarray, n_points: int = DEFAULT_POINTS) -> np.ndarray:
    """The polyline through the raw points, sampled at n equally spaced arc lengths (n, 2)."""
    pts = _distinct(raw)
    if len(pts) == 1:
        return np.repeat(pts, n_points, axis=0)
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    u = np.linspace(0.0, s[-1], n_points)
    return np.column_stack([np.interp(u, s, pts[:, 0]), np.interp(u, s, pts[:, 1])])


def bspline_smooth(raw: np.ndarray, n_points: int = DEFAULT_POINTS, smoothing: float = DEFAULT_SMOOTHING,
                   degree: int = DEGREE) -> np.ndarray:
    """Smoothed heel path (n_points, 2) through the raw agent points (M, 2), metres."""
    pts = _distinct(raw)
    if len(pts) <= 2:
        return linear_resample(pts, n_points)
    k = min(degree, len(pts) - 1)
    w = np.ones(len(pts))
    w[0] = w[-1] = END_WEIGHT
    tck, _ = splprep([pts[:, 0], pts[:, 1]], w=w, k=k, s=smoothing)
    y, z = splev(np.linspace(0.0, 1.0, n_points), tck)
    out = np.column_stack([y, np.maximum(z, 0.0)])
    out[0] = pts[0]
    out[-1] = pts[-1]
    return out
