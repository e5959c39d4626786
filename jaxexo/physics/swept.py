"""Exact clearance of the flat foot while it moves between two samples, so that a safe swing is safe
under any finer look; written for the array module ``xp`` (numpy, jax.numpy). Every function
broadcasts: h0, h1 (..., 2), outline (..., K, 2). ``swept_clearance`` is signed like
``geometry.foot_clearance``. The method: docs/safety.md#a-safe-swing-the-trajectory-checks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxexo.physics.geometry import (
    _inv_edge_len2,
    _point_edge_dist2,
    any_last,
    foot_clearance,
    is_jax,
    min_last,
    vertex_loop,
)


def _last_axis(xp, *arrays):
    """xp.stack(arrays, axis=-1) for arrays of one shape, as one concatenate (NumPy's stack is a
    Python function with a cost per call, and one path's check makes dozens; docs/decisions.md)."""
    return xp.concatenate([a[..., None] for a in arrays], axis=-1)


def _parallelogram(xp, h0, h1, foot_length):
    """The region the foot sweeps from heel h0 to heel h1, as tuples of four arrays (...,): its
    corners (py, pz) (the heel and the toe at h0 and at h1) and its sides a -> a + u (ay, az, uy, uz,
    inv_u) (the foot at h0 and at h1, the heel's and the toe's chords); and, for the inside test,
    (y0, z0, dy, safe_dz, f_safe, has_area)."""
    y0, z0 = h0[..., 0], h0[..., 1]
    dy, dz = h1[..., 0] - y0, h1[..., 1] - z0
    f = foot_length + 0.0 * y0
    zero = 0.0 * z0
    corners = ((y0, y0 + f, y0 + dy, y0 + f + dy), (z0, z0, z0 + dz, z0 + dz))
    ay, az = (y0, y0 + dy, y0, y0 + f), (z0, z0 + dz, z0, z0)
    uy, uz = (f, f, dy, dy), (zero, zero, dz, dz)
    inv_u = tuple(_inv_edge_len2(xp, a, b) for a, b in zip(uy, uz))
    # Only a move with a vertical component has an interior: v - h0 = s (f, 0) + t (dy, dz).
    has_area = xp.abs(dz) > 0.0
    inside = (y0, z0, dy, xp.where(has_area, dz, 1.0), xp.where(f > 0.0, f, 1.0), has_area)
    return corners, (ay, az, uy, uz, inv_u), inside


def _crosses(ay, az, uy, uz, cy, cz, ey, ez):
    """Proper crossing of the side a -> a + u and the outline edge c -> c + e (strict orientation
    tests; touching cases are caught by the endpoint distances being zero)."""
    o1 = uy * (cz - az) - uz * (cy - ay)
    o2 = uy * (cz + ez - az) - uz * (cy + ey - ay)
    o3 = ey * (az - cz) - ez * (ay - cy)
    o4 = ey * (az + uz - cz) - ez * (ay + uy - cy)
    return (o1 * o2 < 0.0) & (o3 * o4 < 0.0)


def _vertex_inside(vy, vz, y0, z0, dy, safe_dz, f_safe, has_area):
    """Whether outline vertices (vy, vz) lie in the parallelogram (s, t in [0, 1])."""
    t = (vz - z0) / safe_dz
    s = (vy - y0 - t * dy) / f_safe
    return (t >= 0.0) & (t <= 1.0) & (s >= 0.0) & (s <= 1.0) & has_area


def swept_distance(xp, h0, h1, foot_length, outline):
    """Exact minimum distance (m) between the region the flat foot sweeps from heel h0 to heel h1
    (a parallelogram) and the outline polyline; zero when they meet. Shapes: (..., 2), (..., K, 2).
    Every term at once, broadcast over (corner or side, edge or vertex): few array operations, the
    form for NumPy (``swept_distance_by_edge`` is the same equation for XLA)."""
    vy = outline[..., 0]
    vz = outline[..., 1]
    # Outline edges c -> c + e, (..., 1, K-1): a leading axis of 1 for P's sides or corners.
    cy, cz = vy[..., None, :-1], vz[..., None, :-1]
    ey, ez = vy[..., None, 1:] - cy, vz[..., None, 1:] - cz
    inv_e = _inv_edge_len2(xp, ey, ez)
    (py, pz), (ay, az, uy, uz, inv_u), (y0, z0, dy, safe_dz, f_safe, has_area) = _parallelogram(
        xp, h0, h1, foot_length
    )
    # Corners and sides (..., 4, 1) against the outline's edges (..., 1, K-1) and vertices (..., 1, K).
    py, pz, ay, az, uy, uz, inv_u = (
        _last_axis(xp, *x)[..., :, None] for x in (py, pz, ay, az, uy, uz, inv_u)
    )
    d_corner = _point_edge_dist2(xp, py, pz, cy, cz, ey, ez, inv_e)
    d_vertex = _point_edge_dist2(xp, vy[..., None, :], vz[..., None, :], ay, az, uy, uz, inv_u)
    crossing = any_last(xp, _crosses(ay, az, uy, uz, cy, cz, ey, ez), axes=2)
    inside = any_last(
        xp,
        _vertex_inside(
            vy,
            vz,
            y0[..., None],
            z0[..., None],
            dy[..., None],
            safe_dz[..., None],
            f_safe[..., None],
            has_area[..., None],
        ),
    )
    d2 = xp.minimum(min_last(xp, d_corner, axes=2), min_last(xp, d_vertex, axes=2))
    return xp.where(crossing | inside, 0.0, xp.sqrt(d2))


def swept_distance_by_edge(xp, h0, h1, foot_length, vy, vz):
    """``swept_distance`` term by term: one outline vertex and edge at a time against the four
    corners and sides, the minimum and the crossing and inside flags carried along; each term is the
    same expression as there. Why: under XLA on a CPU the broadcast form materialises (..., 4, K)
    arrays that leave the cache for thousands of (environment, move) pairs; this form keeps arrays
    of the batch's shape (for the shield's mask, jaxexo.shield.batched, and the environment's step:
    docs/benchmarks.md#training). The outline comes vertex-major, ``vy``, ``vz`` (K, ...)
    broadcasting against the heels' (...,): a vertex row is then contiguous, where column k of a
    (..., K, 2) array is a slower strided access (docs/decisions.md). Under JAX the vertices are a
    ``fori_loop`` (a few unrolled per iteration: most of the speed of a full unroll at a fraction of
    its compile time)."""
    vy, vz = xp.asarray(vy), xp.asarray(vz)  # indexed by the loop's counter
    (py, pz), (ay, az, uy, uz, inv_u), inside = _parallelogram(xp, h0, h1, foot_length)

    def vertex(k, d2, hit):
        wy, wz = vy[k], vz[k]
        for i in range(4):
            d2 = xp.minimum(d2, _point_edge_dist2(xp, wy, wz, ay[i], az[i], uy[i], uz[i], inv_u[i]))
        return d2, hit | _vertex_inside(wy, wz, *inside)

    def vertex_and_edge(k, carry):
        d2, hit = vertex(k, *carry)
        cy, cz = vy[k], vz[k]
        ey, ez = vy[k + 1] - cy, vz[k + 1] - cz
        inv_e = _inv_edge_len2(xp, ey, ez)
        for i in range(4):
            d2 = xp.minimum(d2, _point_edge_dist2(xp, py[i], pz[i], cy, cz, ey, ez, inv_e))
            hit = hit | _crosses(ay[i], az[i], uy[i], uz[i], cy, cz, ey, ez)
        return d2, hit

    k_last = vy.shape[0] - 1
    shape = xp.broadcast_shapes(py[0].shape, vy.shape[1:])
    carry = (xp.full(shape, np.inf, dtype=py[0].dtype), xp.zeros(shape, dtype=bool))
    d2, hit = vertex(k_last, *vertex_loop(xp, k_last, vertex_and_edge, carry))
    return xp.where(hit, 0.0, xp.sqrt(d2))


def swept_clearance(xp, h0, h1, foot_length, outline, c0=None, c1=None):
    """Signed clearance (m) of the foot over the whole move h0 -> h1: the exact swept distance, or the
    (negative) clearance at an end where the foot is inside the obstacle. ``c0``, ``c1``: the ends'
    ``geometry.foot_clearance`` when the caller has them already."""
    if c0 is None:
        c0 = foot_clearance(xp, h0, foot_length, outline)
    if c1 is None:
        c1 = foot_clearance(xp, h1, foot_length, outline)
    if is_jax(xp):  # XLA: the environment checks every step's move this way
        d = swept_distance_by_edge(
            xp,
            h0,
            h1,
            foot_length,
            xp.moveaxis(outline[..., 0], -1, 0),
            xp.moveaxis(outline[..., 1], -1, 0),
        )
    else:
        d = swept_distance(xp, h0, h1, foot_length, outline)
    return xp.minimum(d, xp.minimum(c0, c1))


def swept_lower_bound(xp, c0, c1, move_length):
    """A lower bound (m) on ``swept_clearance`` of a move of length ``move_length`` whose ends have
    foot clearances c0, c1 > 0, without the geometry (used to skip moves that cannot be the closest).

    The foot at h0 + t d is the foot at h0 moved by t d, and the distance to a fixed set is
    1-Lipschitz, so every point of it is at least c0 - t |d| from the outline, and (from the other
    end) at least c1 - (1 - t) |d|. The larger of the two is smallest where they are equal:
    swept distance >= (c0 + c1 - |d|) / 2 (and the clearance is also <= min(c0, c1)). Not valid
    for an end inside the obstacle (c <= 0), where the exact clearance is min(c0, c1) anyway."""
    return 0.5 * (c0 + c1 - move_length)


def path_swept_min(path, foot_length, outline, point_clearance, slack=1e-9):
    """NumPy: per-move clearances (B, N-1) of heel paths (B, N, 2) on outlines (B, K, 2) that agree
    with ``path_swept_clearance`` where the verdict looks: each path's minimum and the move attaining
    it are exact. A move whose ``swept_lower_bound`` exceeds its path's smallest end clearance (an
    upper bound on the minimum) by more than ``slack`` cannot be the closest; it gets that lower
    bound (above the minimum) instead of the exact value, so only the few candidate moves of all
    paths go through the geometry, in one vectorised call. Moves with an end inside the obstacle
    get min(c0, c1), which is exact there."""
    c = point_clearance
    c0, c1 = c[:, :-1], c[:, 1:]
    ends = np.minimum(c0, c1)
    d = path[:, 1:] - path[:, :-1]
    length = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])
    lb = swept_lower_bound(np, c0, c1, length)
    out = np.maximum(lb, 0.0)
    if ends.shape[1] == 0:
        return out
    upper = ends.min(axis=1, keepdims=True)
    inside = ends <= 0.0
    out[inside] = ends[inside]
    r, j = np.nonzero(~inside & (lb <= upper + slack))
    if r.size:
        out[r, j] = np.minimum(
            swept_distance(np, path[r, j], path[r, j + 1], foot_length, outline[r]), ends[r, j]
        )
    return out


def box_lower_bound(heel, foot_length, outline):
    """NumPy: a lower bound (m) on ``geometry.foot_clearance`` of the foot at heels (B, N, 2) from
    outlines (B, K, 2), positive only where it is a bound on a foot outside the obstacle.

    The outline and the region under it (down to the ground) lie in the box [min y, max y] x
    [min(0, min z), max z], so the distance from the foot segment to that box is at most the distance
    to the outline, and a foot at a positive distance from the box is not inside the obstacle."""
    vy, vz = outline[..., 0], outline[..., 1]
    y0, y1 = vy.min(axis=-1)[:, None], vy.max(axis=-1)[:, None]
    z0, z1 = np.minimum(vz.min(axis=-1), 0.0)[:, None], vz.max(axis=-1)[:, None]
    hy, hz = heel[..., 0], heel[..., 1]
    dy = np.maximum(np.maximum(y0 - (hy + foot_length), hy - y1), 0.0)
    dz = np.maximum(np.maximum(z0 - hz, hz - z1), 0.0)
    return np.sqrt(dy * dy + dz * dz)


def path_clearance_pruned(path, foot_length, outline, slack=1e-9, below=None):
    """NumPy: (point clearances (B, N), per-move clearances (B, N-1)) of heel paths (B, N, 2) on
    outlines (B, K, 2) with ``path_swept_min``'s guarantee (each path's minimum over its moves, and
    the move attaining it, exact), computing the exact foot clearance only at the samples that can
    matter. Elsewhere the point clearance is ``box_lower_bound`` (a lower bound, > 0).

    1. the box bound d at every sample; exact clearances where d is within two moves of the
       path's smallest d (always including that sample): their minimum U bounds the path's
       minimum from above (a move's swept clearance is at most its end clearances);
    2. a move whose ``swept_lower_bound`` from its ends' lower bounds exceeds U + slack cannot be
       the closest (the bound is monotone in the end clearances);
    3. the remaining moves get exact end clearances and the exact swept distance.

    ``below`` (B,), optional: moves whose lower bound is under their path's ``below`` are computed
    exactly too, so every move whose clearance is under ``below`` is exact and every other one is
    reported at or above ``below`` (what a caller acting on each move closer than a threshold
    needs: jaxexo.swing.clearing asks for the moves closer than its margin)."""
    b, n = path.shape[:2]
    c = box_lower_bound(path, foot_length, outline)
    if n < 2:
        return foot_clearance(np, path, foot_length, outline[:, None]), np.zeros((b, 0))
    d = path[:, 1:] - path[:, :-1]
    length = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])
    exact = c <= c.min(axis=1, keepdims=True) + 2.0 * length.max(axis=1, keepdims=True)
    r, i = np.nonzero(exact)
    c[r, i] = foot_clearance(np, path[r, i], foot_length, outline[r])
    upper = np.where(exact, c, np.inf).min(axis=1, keepdims=True)
    c0, c1 = c[:, :-1], c[:, 1:]
    ends = np.minimum(c0, c1)
    # An end inside the obstacle (c <= 0) is always exact (d > 0 means outside): min(c0, c1) is
    # then that end's clearance, the exact swept clearance of the move.
    inside = ends <= 0.0
    lb = swept_lower_bound(np, c0, c1, length)
    out = np.maximum(lb, 0.0)
    out[inside] = ends[inside]
    cand = lb <= upper + slack
    if below is not None:
        cand |= lb < np.asarray(below, np.float64).reshape(b, 1)
    r, j = np.nonzero(~inside & cand)
    if r.size:
        for k in (j, j + 1):  # exact clearances at the candidates' ends
            miss = ~exact[r, k]
            if miss.any():
                rm, km = r[miss], k[miss]
                c[rm, km] = foot_clearance(np, path[rm, km], foot_length, outline[rm])
                exact[rm, km] = True
        e = np.minimum(c[r, j], c[r, j + 1])
        out[r, j] = np.minimum(
            swept_distance(np, path[r, j], path[r, j + 1], foot_length, outline[r]), e
        )
    return c, out


def path_swept_clearance(xp, path, foot_length, outline, point_clearance=None):
    """Per-move signed clearance (..., N-1) along heel paths (..., N, 2) taken as polylines;
    ``outline`` (..., K, 2) broadcasts against the path's leading axes (add an axis for the moves)."""
    c = (
        foot_clearance(xp, path, foot_length, outline[..., None, :, :])
        if point_clearance is None
        else point_clearance
    )
    return swept_clearance(
        xp,
        path[..., :-1, :],
        path[..., 1:, :],
        foot_length,
        outline[..., None, :, :],
        c[..., :-1],
        c[..., 1:],
    )


def backward_motion(xp, y):
    """Largest backward heel motion (m) along heel y samples (..., N): max over i < j of y_i - y_j (the
    drop below the running maximum); exact for the polyline through the samples (its extremes are at
    samples). Zero for a path that never moves backward."""
    run = np.maximum.accumulate(np.asarray(y), axis=-1) if xp is np else _cummax(xp, y)
    return xp.max(run - y, axis=-1)


def _cummax(xp, y):
    import jax

    return jax.lax.cummax(y, axis=y.ndim - 1)


# --------------------------------------------------------------------------------------------
# One heel polyline's clearance with few NumPy calls (the timed swing's verdict)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FootReach:
    """The heels whose flat foot [heel, heel + (f, 0)] meets an outline: the outline swept back by
    the foot, a union of parallelograms (each edge with itself moved back by f). Points are complex
    numbers y + iz here (a product or a difference is one NumPy call). The parallelograms' sides lie
    on S segments a + t e, t in [0, 1] (the edges, the edges moved back by f, and the horizontal
    segments from each vertex back by f), rows (1, S), with ``ce`` = conj(e) / |e|^2 (0 for a
    point); the segments' ends are the V points w, a row (1, V); ``box`` (y0, y1, z1): the heels'
    box [y0, y1] x [0, z1] around them. For a heel outside every parallelogram the foot's distance
    to the outline is the heel's distance to the S segments (the heel and the toe to the edges, the
    vertices to the foot); for a heel move that stays outside them, the swept foot's distance is
    the least of its ends' and of the w's distances to the move (the vertices to the heel's and the
    toe's chords), the terms of ``swept_distance``."""

    a: np.ndarray
    e: np.ndarray
    ce: np.ndarray
    w: np.ndarray
    box: tuple


_REACH: dict = {}


def foot_reach(outline: np.ndarray, foot_length: float) -> FootReach:
    """``FootReach`` of an outline (K, 2) (padding repeats dropped), remembered per outline: the
    same scene recurs across a batch."""
    key = (outline.tobytes(), foot_length)
    out = _REACH.get(key)
    if out is None:
        if len(_REACH) > 256:
            _REACH.clear()
        out = _REACH[key] = _foot_reach(np.asarray(outline, np.float64), float(foot_length))
    return out


def _foot_reach(outline: np.ndarray, f: float) -> FootReach:
    if len(outline) > 2 and (outline[-1] == outline[-2]).all():  # padded: repeats dropped
        keep = np.ones(len(outline), bool)
        keep[1:] = np.any(outline[1:] != outline[:-1], axis=1)
        outline = outline[keep]
    v = outline[:, 0] + 1j * outline[:, 1]
    back = v - f
    a = np.concatenate([v[:-1], back, back[:-1]])  # the edges, from each vertex back, moved back
    e = np.concatenate([v[1:], v, back[1:]]) - a
    len2 = e.real * e.real + e.imag * e.imag
    ok = len2 > 1e-24  # shorter: a point (as geometry._inv_edge_len2)
    ce = np.where(ok, e.conj() / np.where(ok, len2, 1.0), 0.0)
    return FootReach(
        a=a[None],
        e=e[None],
        ce=ce[None],
        w=np.concatenate([v, back])[None],
        box=(float(back.real.min()), float(outline[:, 0].max()), float(outline[:, 1].max())),
    )


def _segment_distance2(p, a, e, ce) -> np.ndarray:
    """Squared distances of points p to segments a + t e, t in [0, 1] (complex, broadcast;
    ce = conj(e) / |e|^2): the rows' least (M,)."""
    ap = p - a
    t = (ap * ce).real
    w = ap - np.minimum(np.maximum(t, 0.0), 1.0) * e
    return (w.real * w.real + w.imag * w.imag).min(axis=1)


def polyline_clearances(heel, foot_length, outline, step: float = 0.02, slack: float = 1e-9):
    """NumPy, one heel path (N, 2): (point clearances (N,), per-move clearances (N-1,)) with
    ``path_swept_min``'s guarantee for the moves (the smallest move and its value exact; elsewhere
    lower bounds above it; the points' are lower bounds), or None where this shortcut does not
    apply (the caller then takes the exact functions): a heel below the floor, the first heel in
    the outline's box, or a stretch of the path that may come within reach of the outline (a
    swing that touches it, or nearly).

    The distances d to the ``FootReach`` segments of the first heel at or past each multiple of
    ``step`` (m) along the path, and of the last. The path between two of them, a length l apart
    along it, keeps at least g = (d_a + d_b - l) / 2 from the segments (the distance is
    1-Lipschitz). Where every g > 0 the path never meets a segment, so, from a first heel outside
    the box (hence outside the reach and the obstacle), it never enters the reach, and a heel's or
    a move's distance to the segments is the foot's clearance there. The moves of a stretch whose
    g is not over the least d (an upper bound on the smallest move) get their exact clearance: the
    least of their ends' distances and the w points' distances to the move (``swept_distance``'s
    terms); the others g, below their clearance and above the smallest."""
    r = foot_reach(outline, foot_length)
    n = len(heel)
    y0, y1, z1 = r.box
    hy, hz = float(heel[0, 0]), float(heel[0, 1])
    if n < 2 or (y0 <= hy <= y1 and hz <= z1) or not heel[:, 1].min() >= 0.0:
        return None
    p = np.ascontiguousarray(heel, np.float64).view(np.complex128)  # (N, 1): y + iz
    d = p[1:] - p[:-1]
    length = np.sqrt(d.real * d.real + d.imag * d.imag)[:, 0]
    arc = np.zeros(n)
    np.cumsum(length, out=arc[1:])
    if not arc[-1] > 0.0:  # a heel that does not move
        return None
    # The first heel at or past each multiple of step (a long move may repeat one), and the last.
    co = np.concatenate([np.searchsorted(arc, np.arange(0.0, arc[-1], step)), [n - 1]])
    dc = np.sqrt(_segment_distance2(p[co], r.a, r.e, r.ce))
    ac = arc[co]
    g = 0.5 * (dc[:-1] + dc[1:] - (ac[1:] - ac[:-1]))
    if not g.min() > slack:
        return None
    count = co[1:] - co[:-1]  # the moves of each stretch
    j = np.flatnonzero(np.repeat(g <= dc.min() + slack, count))
    m = len(j)
    ends = _segment_distance2(p[np.concatenate([j, j + 1])], r.a, r.e, r.ce)
    u = d[j]
    lj = length[j, None]
    # The w points to the moves (a move of length 0: t = 0, the distance to its start).
    dw = _segment_distance2(r.w, p[j], u, u.conj() / np.maximum(lj * lj, 1e-300))
    sw = np.repeat(g, count)
    sw[j] = np.sqrt(np.minimum(np.minimum(ends[:m], ends[m:]), dw))
    # A point's clearance is at least that of a move it ends.
    return np.concatenate([sw, sw[-1:]]), sw
