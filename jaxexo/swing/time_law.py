"""The time-optimal passes (TOPP) of a device-ready swing: the rest-to-rest speeds s'^2 of a joint
path on a uniform s grid under the limits' rows (jaxexo.swing.limits), which jaxexo.swing.curve
turns into the smoothed time law s(t). The method: docs/device-timing.md (how timing is computed).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import reduce

import numpy as np

SCALAR_ROWS = 24  # batches up to this size scan row by row as Python floats (faster there)
X_CAP = 1e6  # 1/s^2: cap on s'^2 where no joint moves (s' <= 1000 /s)


def lane_min(x: np.ndarray) -> np.ndarray:
    """``x.min(axis=-1)`` over a short last axis (the joints), column by column: the same values
    (a minimum is exact, in any order; NaN propagates either way), where NumPy's reduction across
    a short row costs many times more."""
    return reduce(np.minimum, (x[..., j] for j in range(x.shape[-1])))


def lane_max(x: np.ndarray) -> np.ndarray:
    """``x.max(axis=-1)`` over a short last axis, column by column (``lane_min``)."""
    return reduce(np.maximum, (x[..., j] for j in range(x.shape[-1])))


# --------------------------------------------------------------------------------------------
# Time-optimal parametrisation (TOPP) on a grid
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Rows:
    """Constraint rows at each grid point, a, b, c (B, K, R): m = a s' (order 1) or m = a s'' +
    b s'^2 + c (order 2; c None: no offset), each |m| <= bound (R,) (None: a constraint's own)."""

    a: np.ndarray
    b: np.ndarray | None = None
    c: np.ndarray | None = None
    bound: np.ndarray | None = None


def _lines(rows: Rows):
    """Per grid point and row, the admissible s'' as lines in x = s'^2 (B, K, R) each: which rows
    bound s'' (a != 0), k = b / a, and U = up - k x, L = -down - k x, up and down = (bound -+
    sign(a) c) / |a| (inf where a row does not bound s'')."""
    a = rows.a
    moving = np.abs(a) > 1e-12
    mag = np.where(moving, np.abs(a), 1.0)
    k = np.where(moving, rows.b / np.where(moving, a, 1.0), 0.0)
    if rows.c is None:
        up = np.where(moving, rows.bound / mag, np.inf)
        return moving, k, up, up
    shift = np.sign(a) * rows.c
    up, down = (np.where(moving, (rows.bound + f * shift) / mag, np.inf) for f in (-1.0, 1.0))
    return moving, k, up, down


def max_speed_curve(rows: Rows, lines=None) -> np.ndarray:
    """Largest admissible x = s'^2 at each grid point (..., K) for ``rows`` (..., K, R): the rows
    with a = 0 (|b x + c| <= bound), and the condition that some s'' satisfies every row
    (L_i(x) <= U_j(x) for every pair, each linear in x). ``lines``: ``_lines(rows)`` when known."""
    moving, k, up, down = _lines(rows) if lines is None else lines
    b = rows.b
    still = rows.bound if rows.c is None else rows.bound - np.sign(b) * rows.c
    with np.errstate(divide="ignore"):
        # Rows that do not bound s'': |b x + c| <= bound.
        still = lane_min(
            np.where(~moving & (np.abs(b) > 0), still / np.abs(np.where(moving, 1.0, b)), np.inf)
        )
        slope = k[..., None, :] - k[..., :, None]  # (..., i, j): (k_j - k_i) x <= down_i + up_j
        room = down[..., :, None] + up[..., None, :]
        x_acc = lane_min(
            lane_min(np.where(slope > 0, room / np.where(slope > 0, slope, 1.0), np.inf))
        )
    return np.minimum(still, np.minimum(x_acc, X_CAP))


def _affine_steps(lines, ds):
    """Per grid point and row, the passes' update as affine maps of x = s'^2 (B, K, R) each:
    forward x + 2 ds U(x) = min_j (fa_j x + fb_j), backward x - 2 ds L(x) = min_j (ba_j x + bb_j),
    from ``_lines``' U_j(x) = up_j - k_j x and L_j(x) = -down_j - k_j x (inf: no bound)."""
    _, k, up, down = lines
    return 1.0 - 2.0 * ds * k, 2.0 * ds * up, 1.0 + 2.0 * ds * k, 2.0 * ds * down


def _far_end_steps(fa, fb, ba, bb):
    """The passes' steps (``_affine_steps``) with each cell's acceleration limits held at its far end
    too: a step of s'' = u from x over a cell needs u <= U_j(x + 2 ds u) = up_j - k_j (x + 2 ds u) at
    the next point, i.e. x + 2 ds u <= (x + 2 ds up_j) / (1 + 2 ds k_j) where 1 + 2 ds k_j > 0 (else
    the far end bounds nothing this way), and the backward step likewise with L at the point before.
    Each step becomes the minimum over 2 J affine maps (B, K, 2 J), the far end's moved to the
    position the scan steps from: forward from point i, the maps of point i + 1; backward from point
    i, those of point i - 1."""
    # From the near-end maps: 2 ds k = 1 - fa = ba - 1, 2 ds up = fb and 2 ds down = bb.
    grow = np.concatenate([ba[:, 1:], ba[:, -1:]], axis=1)  # 1 + 2 ds k at the next point
    shrink = np.concatenate([fa[:, :1], fa[:, :-1]], axis=1)  # 1 - 2 ds k at the point before
    r_next = np.concatenate([fb[:, 1:], fb[:, -1:]], axis=1)
    r_prev = np.concatenate([bb[:, :1], bb[:, :-1]], axis=1)
    fwd_ok, bwd_ok = grow > 0.0, shrink > 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        fa2 = np.where(fwd_ok, 1.0 / np.where(fwd_ok, grow, 1.0), 0.0)
        ba2 = np.where(bwd_ok, 1.0 / np.where(bwd_ok, shrink, 1.0), 0.0)
        fb2 = np.where(fwd_ok, r_next * fa2, np.inf)
        bb2 = np.where(bwd_ok, r_prev * ba2, np.inf)
    cat = lambda u, v: np.concatenate([u, v], axis=-1)  # noqa: E731
    return cat(fa, fa2), cat(fb, fb2), cat(ba, ba2), cat(bb, bb2)


def _from_bound(a, b, bound):
    """Per step of a scan in order (a, b (K, J), bound (K,)): where a step from x = bound[p] lands
    (clipped as the scan clips), and whether that table may stand for the step (no NaN: the scan's
    comparisons skip a NaN, a minimum does not). Column by column: a reduction across a short row
    is several times slower in NumPy, and a minimum is the same in any order."""
    y = np.minimum(bound[1:], lane_min(a[:-1] * bound[:-1, None] + b[:-1]))
    return np.where(y > 0.0, y, 0.0), ~np.isnan(y)


def _scan_floats(a, b, bound, order, start: float = 0.0) -> np.ndarray:
    """One path's scan (K, J) as Python floats (``_min_affine_scan``), from x = ``start``. A step from a point on its
    bound lands where ``_from_bound`` says, so a run of such steps that each land on their bound
    again (the passes riding the limit curve: two steps in three) is jumped over in one slice."""
    k, nj = a.shape
    order = np.asarray(order)
    a, b, bound = a[order], b[order], bound[order]  # in scan order: position p steps to p + 1
    fb, usable = _from_bound(a, b, bound)
    chain = usable & (fb == bound[1:])
    # Per position, the first position at or after it whose step leaves the bound (or k - 1).
    breaks = np.append(np.flatnonzero(~chain), k - 1)
    next_break = breaks[np.searchsorted(breaks, np.arange(k - 1))].tolist()
    ub, fb, chain, usable = bound.tolist(), fb.tolist(), chain.tolist(), usable.tolist()
    af, bf = a.ravel().tolist(), b.ravel().tolist()  # flat: row p is [p * nj, (p + 1) * nj)
    out = [0.0] * k
    xi = out[0] = float(start)
    p = 0
    while p < k - 1:
        if xi == ub[p] and usable[p]:
            if chain[p]:
                q = next_break[p]  # steps p .. q - 1 each land on their bound
                out[p + 1 : q + 1] = ub[p + 1 : q + 1]
                xi, p = ub[q], q
                continue
            xi = fb[p]
        else:
            y = ub[p + 1]
            for j in range(p * nj, (p + 1) * nj):
                t = af[j] * xi + bf[j]
                if t < y:
                    y = t
            xi = y if y > 0.0 else 0.0
        p += 1
        out[p] = xi
    res = np.empty(k)
    res[order] = out
    return res


def _min_affine_scan(a, b, bound, order, start=None):
    """x_next = clip(min_j (a_j x + b_j), 0, bound) over the grid points in ``order``, from x = 0
    (or ``start`` (B,): a moving start, kept as it is even above its bound), for a batch: a, b
    (B, K, J), bound (B, K). Returns x (B, K). A small batch runs row by row as
    Python floats, where a grid point's few float operations cost less than a vectorised step's
    several NumPy calls (docs/decisions.md); a large one runs one vectorised step per grid point.
    Both do the same IEEE operations (a product, a sum, exact minima), so they agree bit for bit."""
    bsz, k, nj = a.shape
    x = np.empty((bsz, k))
    start = np.zeros(bsz) if start is None else np.asarray(start, np.float64)
    if bsz <= SCALAR_ROWS:
        for row in range(bsz):
            x[row] = _scan_floats(a[row], b[row], bound[row], order, start[row])
        return x
    x[:, order[0]] = start
    for src, dst in zip(order[:-1], order[1:]):
        y = (a[:, src] * x[:, src, None] + b[:, src]).min(axis=-1)
        x[:, dst] = np.clip(y, 0.0, bound[:, dst])
    return x


def topp(
    rows: Rows,
    ds: float,
    cap: np.ndarray | None = None,
    *,
    both_ends: bool = False,
    start: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The time-optimal rest-to-rest law on a uniform s grid (spacing ds) under ``rows``
    (B, K, R: jaxexo.swing.limits.passes_rows): s'^2 (B, K), and per cell the least speed (B, K-1)
    of a cell crossed from rest to rest (the passes: module docstring). ``cap`` (B, K): further
    upper bounds on s'^2 (the speed limits'). ``both_ends``: each cell's constant s'' within the
    rows at both of its ends (``_far_end_steps``), not only where the pass enters it: on a coarse
    grid the far end's excess, first order in ds, is what the check would otherwise slow the swing
    for. ``start`` (B,): s'^2 at the first grid point of a law that starts moving (a swing
    replanned in flight, jaxexo.swing.replan), kept there; None: from rest."""
    lines = _lines(rows)
    xmax = max_speed_curve(rows, lines)
    if cap is not None:
        xmax = np.minimum(xmax, cap)
    b, k = xmax.shape
    fa, fb, ba, bb = _affine_steps(lines, ds)
    if both_ends:
        fa, fb, ba, bb = _far_end_steps(fa, fb, ba, bb)
    # Backward from rest at the end: reach[i-1] = clip(reach[i] - 2 ds L_i(reach[i]), 0, xmax[i-1]).
    backward = list(range(k - 1, -1, -1))
    reach = _min_affine_scan(ba, bb, xmax, backward)
    # Forward from rest (or the given start) under the reachable speeds.
    x = _min_affine_scan(fa, fb, reach, list(range(k)), start)
    # A cell entered and left at rest (a cusp, or the two ends of a very short path) takes
    # 2 sqrt(ds / u0) at the largest s'' from rest, u0 = min_j up_j: its mean speed is
    # sqrt(ds u0) / 2.
    u0 = lane_min(lines[2][:, :-1])
    floor = 0.5 * np.sqrt(ds * np.minimum(u0, X_CAP))
    if cap is not None:
        # A capped cell (see time_swings) is crossed no faster than its caps allow, cusps included.
        root = np.sqrt(cap)
        floor = np.minimum(floor, 0.5 * (root[:, :-1] + root[:, 1:]))
    return x, floor
