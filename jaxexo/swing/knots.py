"""The joint path in few pieces (NumPy only): a C2 cubic spline through the subset of a swing's
joint samples that its geometry needs, chosen so that the spline stays within a tolerance of every
sample (the heel in metres, each joint in radians). Used by jaxexo.swing.timing; the method and
the measurements: docs/device-timing.md ("The joint path in few pieces").
"""

from __future__ import annotations

import numpy as np

from jaxexo.swing.curve import JointPath, cubic_paths, cubic_paths_ragged, paths_at
from jaxexo.swing.time_law import lane_max

# The spline may stray from a joint sample by at most these (checked at every sample):
# - the heel: a tenth of the 0.5 mm the generators keep above the clearance margin for the curve
#   through their samples (the same 0.05 mm the verdict's polyline is allowed: timing.CURVE_TOL);
TOL_HEEL = 5e-5  # m
# - each joint: a fifth of the joint-range check's slack at a straight knee (kinematics.ANGLE_EPS,
#   1e-4 rad: a straight leg is exactly at the knee's 0 limit at lift-off and touch-down).
TOL_JOINT = 2e-5  # rad
# The first and last this many sample intervals are kept as they are: there the legs straighten on
# the floor (the joints move like a square root of the heel's height). With 0 an end piece dipped
# the heel below the floor by up to 0.04 um; with 2, by 1.3 pm near touch-down (more than the
# kinematics' rounding that tests/test_swing_curve.py allows, 1 pm); with 4, by 0.5 pm at most,
# as the spline through every sample did (0.56 pm), on the tests' swings.
END_KNOTS = 4
# The first knots: every STRIDE-th sample (and the ends, END_KNOTS). A choice made from the samples'
# values (an estimate of the spline's error from their fourth differences) moved with the rounding
# of the stance leg's inverse kinematics (its knee nearly straight mid-swing: a 1e-16 m change of
# the heel moves those joint samples by 1e-7 rad), and with it the knots and the whole timed swing
# (up to 1e-2 rad, a control period, in 9 % of swings); a fixed stride does not, and the rounds
# below insert knots only where the spline strays (tests/test_reference_outputs.py's probe).
STRIDE = 4
ROUNDS = 6  # rounds of inserting knots where the spline strays; then every sample is a knot
FEWEST = 8  # a path of at most this many samples keeps them all


# q @ _PHASES: the legs' segment angles phi = (q0, q0 + q1, q2, q2 + q3) (curve.segments).
_PHASES = np.array([[1.0, 1.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.0], [0, 0, 0, 1]])


def _score(dq: np.ndarray, lengths) -> np.ndarray:
    """Per row of joint differences dq (n, 4), the larger of the heel's displacement bound over
    TOL_HEEL and max_j |dq_j| over TOL_JOINT. The bound: the heel is a sum of L_i e(phi_i) with
    L = (thigh, shin, thigh, shin) and e a unit vector, and |e(a) - e(b)| <= |a - b|, so the heel
    moves by at most sum_i L_i |d phi_i|."""
    thigh, shin = lengths
    heel = np.abs(dq @ _PHASES) @ (np.array([thigh, shin, thigh, shin]) / TOL_HEEL)
    return np.maximum(heel, lane_max(np.abs(dq)) / TOL_JOINT)


def _first_knots(n: int) -> np.ndarray:
    """Indices of the first knots of n samples: every STRIDE-th, and the first and last END_KNOTS
    sample intervals whole."""
    ends = np.r_[np.arange(END_KNOTS + 1), np.arange(n - END_KNOTS - 1, n)]
    return np.unique(np.concatenate([np.arange(0, n, STRIDE), ends]))


def few_knot_path(q: np.ndarray, s: np.ndarray, lengths) -> JointPath:
    """The C2 not-a-knot spline through a subset of the joint samples q (N, 4) at parameters s (N,)
    (increasing, 0 to 1), within TOL_HEEL and TOL_JOINT of every sample: the first knots every STRIDE-th sample
    (``_first_knots``), then, ROUNDS times at most, the sample that strays most in
    each interval over the tolerance made a knot. A path still over it is the spline through every
    sample (exact at them)."""
    return few_knot_paths([q], [s], lengths)[0]


def few_knot_paths(qs: list, ss: list, lengths) -> list[JointPath]:
    """``few_knot_path`` of several swings (q (N_b, 4), s (N_b,) each), their rounds' splines
    solved together (curve.cubic_paths_ragged) and evaluated together: each swing gets the very
    path it gets alone."""
    out: list = [None] * len(qs)
    idx = {}
    for b, (q, s) in enumerate(zip(qs, ss)):
        if len(s) <= FEWEST + 2 * END_KNOTS:
            out[b] = cubic_paths(s[None], q[None])[0]
        else:
            idx[b] = _first_knots(len(s))
    for _ in range(ROUNDS):
        if not idx:
            return out
        todo = list(idx)
        paths = cubic_paths_ragged(
            [np.take(ss[b], idx[b]) for b in todo], [np.take(qs[b], idx[b], axis=0) for b in todo]
        )
        values = paths_at(paths, [ss[b] for b in todo], 0)
        for b, path, (v,) in zip(todo, paths, values):
            score = _score(v - qs[b], lengths)
            over = score > 1.0
            if not over.any():
                out[b] = path
                del idx[b]
                continue
            # Per knot interval, its sample that strays most (the intervals' samples are
            # contiguous).
            piece = np.searchsorted(idx[b], np.arange(len(score)), side="right") - 1
            worst = np.flatnonzero(over)
            worst = worst[np.lexsort((score[worst], piece[worst]))]
            last = np.r_[piece[worst][1:] != piece[worst][:-1], True]
            idx[b] = np.union1d(idx[b], worst[last])
    if idx:  # still over the tolerance: the spline through every sample
        for b, path in zip(idx, cubic_paths_ragged([ss[b] for b in idx], [qs[b] for b in idx])):
            out[b] = path
    return out
