"""The joint path in few pieces (NumPy only): a C2 cubic spline through the subset of a swing's
joint samples that its geometry needs, chosen so that the spline stays within a tolerance of every
sample (the heel in metres, each joint in radians). Used by jaxexo.swing.timing; the method and
the measurements: docs/device-timing.md ("A swing in few pieces").
"""

from __future__ import annotations

import numpy as np

from jaxexo.swing.curve import JointPath, cubic_paths, paths_at
from jaxexo.swing.time_law import lane_max

# The spline may stray from a joint sample by at most these (checked at every sample):
# - the heel: a tenth of the 0.5 mm the generators keep above the clearance margin for the curve
#   through their samples (the same 0.05 mm the verdict's polyline is allowed: timing.CURVE_TOL);
TOL_HEEL = 5e-5  # m
# - each joint: a fifth of the joint-range check's slack at a straight knee (kinematics.ANGLE_EPS,
#   1e-4 rad: a straight leg is exactly at the knee's 0 limit at lift-off and touch-down).
TOL_JOINT = 2e-5  # rad
# The first and last this many sample intervals are kept as they are: there the legs straighten on
# the floor (the joints move like a square root of the heel's height), where a longer end piece
# could dip the heel below the floor by a few hundredths of a micrometre.
END_KNOTS = 2
# The first knots are spread by an estimate of the spline's error, h^4 |q''''| / 384 per interval
# of length h (q'''' from the samples' fourth divided differences), this much denser than it asks.
DENSITY = 1.5
ROUNDS = 4  # rounds of inserting knots where the spline strays; then every sample is a knot
FEWEST = 8  # a path of at most this many samples keeps them all


def heel_bound(dq: np.ndarray) -> np.ndarray:
    """Per row of joint differences dq (n, 4), the weights (n, 4) whose sum with (thigh, shin,
    thigh, shin) bounds the heel's displacement: the heel is a sum of L_i e(phi_i) with
    phi = (q0, q0 + q1, q2, q2 + q3), and |e(a) - e(b)| <= |a - b| for a unit vector e."""
    return np.abs(np.stack([dq[:, 0], dq[:, 0] + dq[:, 1], dq[:, 2], dq[:, 2] + dq[:, 3]], axis=1))


def _score(dq: np.ndarray, lengths) -> np.ndarray:
    """Per row (n,), the largest of the heel bound over TOL_HEEL and |dq_j| over TOL_JOINT."""
    thigh, shin = lengths
    w = np.array([thigh, shin, thigh, shin]) / TOL_HEEL
    return np.maximum(heel_bound(dq) @ w, lane_max(np.abs(dq)) / TOL_JOINT)


def _first_knots(q: np.ndarray, s: np.ndarray, lengths) -> np.ndarray:
    """Indices of the first knots: spread so that each interval's estimated error h^4 |q''''| / 384
    is about the tolerance, with ``_score``'s weights (the ends kept: END_KNOTS)."""
    n = len(s)
    d = q
    for k in range(1, 5):  # divided differences: the fourth, times 4!, estimates q''''
        d = np.diff(d, axis=0) / (s[k:] - s[:-k])[:, None]
    m = _score(24.0 * d, lengths)  # (n - 4,): the fourth difference over samples i .. i + 4
    # Per sample interval, the largest estimate among the stencils that span it.
    need = np.zeros(n - 1)
    for o in range(4):
        need[o : o + n - 4] = np.maximum(need[o : o + n - 4], m)
    per_s = DENSITY * (need / 384.0) ** 0.25  # knots per unit of s
    count = np.concatenate([[0.0], np.cumsum(per_s * np.diff(s))])
    at = np.searchsorted(count, np.arange(1.0, count[-1]))
    ends = np.r_[np.arange(END_KNOTS + 1), np.arange(n - END_KNOTS - 1, n)]
    return np.unique(np.concatenate([ends, at]))


def few_knot_path(q: np.ndarray, s: np.ndarray, lengths) -> JointPath:
    """The C2 not-a-knot spline through a subset of the joint samples q (N, 4) at parameters s (N,)
    (increasing, 0 to 1), within TOL_HEEL and TOL_JOINT of every sample: the first knots from the
    error estimate (``_first_knots``), then, ROUNDS times at most, the sample that strays most in
    each interval over the tolerance made a knot. A path still over it is the spline through every
    sample (exact at them)."""
    n = len(s)
    if n <= FEWEST + 2 * END_KNOTS:
        return cubic_paths(s[None], q[None])[0]
    idx = _first_knots(q, s, lengths)
    for _ in range(ROUNDS):
        (path,) = cubic_paths(np.take(s, idx)[None], np.take(q, idx, axis=0)[None])
        score = _score(paths_at([path], [s], 0)[0][0] - q, lengths)
        over = score > 1.0
        if not over.any():
            return path
        # Per knot interval, its sample that strays most (the intervals' samples are contiguous).
        piece = np.searchsorted(idx, np.arange(n), side="right") - 1
        worst = np.flatnonzero(over)
        order = np.lexsort((score[worst], piece[worst]))
        worst = worst[order]
        last = np.r_[piece[worst][1:] != piece[worst][:-1], True]
        idx = np.union1d(idx, worst[last])
    return cubic_paths(s[None], q[None])[0]
