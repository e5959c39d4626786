"""Smoothing that keeps the margin: the thesis's B-spline (jaxexo.swing.smoothing) corrected as little
as possible where it comes closer to the obstacle than the margin or moves the heel backward, many
paths at once (``clear_rows``; ``exact_clear_rows``, every move exact, is its reference). Method:
docs/generation.md (the fit and the correction).
"""

from __future__ import annotations

import numpy as np

from jaxexo.physics import geometry, swept
from jaxexo.swing import smoothing as sm

ROUNDS = 4
SLACK = 1e-3  # m asked above the margin, so that the next round's curve does not land on it
_GROW = 1.2  # each round asks this multiple of the shortfall (rounding of the normals)
_ACTIVE_SET_STEPS = 8
_NORMAL_EPS = 1e-4  # m, central-difference step of the clearance gradient
_MIN_DIAG = 1e-9  # relative: constraints with less freedom than this are left to the retries
MAX_SHIFT = 0.10  # m: a correction moving a sample further than this is not a small one; not made
# A correction that needs more constraints than this at once (a curve far inside the margin over most
# of its length: seen only on paths that never reach the goal) is not a small one either; not made,
# which also spares its costly dual solve (docs/generation.md#speed).
MAX_CONSTRAINTS = 64


def _outward(path_points, foot_length, outline):
    """Unit outward normals (k, 2) of the foot's distance to the outline at heel points (k, 2);
    ``outline`` (K, 2), or (k, K, 2): one per point."""
    e = _NORMAL_EPS
    probe = (
        path_points[None, :, :] + np.array([[e, 0.0], [-e, 0.0], [0.0, e], [0.0, -e]])[:, None, :]
    )
    ol = outline[None] if outline.ndim == 3 else outline[None, None]
    c = geometry.foot_clearance(np, probe, foot_length, ol)  # (4, k)
    g = np.stack([c[0] - c[1], c[2] - c[3]], axis=-1)
    norm = np.linalg.norm(g, axis=-1, keepdims=True)
    return np.where(norm > 0.0, g / np.maximum(norm, 1e-300), [0.0, 1.0])


# Smallest ratio of a Cholesky factor's diagonal entries (squared) for which _solve_stack trusts an
# LU solve; below it the matrix may be nearly singular and lstsq's minimum-norm solution is taken.
_PD_RATIO = 1e-10


def _solve_stack(a: np.ndarray, b: np.ndarray, act: np.ndarray) -> np.ndarray:
    """Solutions x of a[act, act] x = b[act] for a stack of small symmetric positive semi-definite a
    (G, k, k), b (G, k) and the active constraints ``act`` (G, k) (x = 0 elsewhere). Each system is
    solved on its active constraints alone, in stacks of one size (LAPACK's arithmetic depends on
    the size, so a path gets the same numbers in any batch as on its own: these systems can be
    ill-conditioned enough to amplify a last-bit difference)."""
    g, k = act.shape
    x = np.zeros((g, k))
    if g == 1:  # one swing: the same system, fewer NumPy calls
        on = np.flatnonzero(act[0])
        if on.size:
            x[0, on] = _solve_same(a[0][on[:, None], on][None], b[0, on][None])[0]
        return x
    order = np.argsort(~act, axis=1, kind="stable")  # each row's active constraints first, in order
    count = act.sum(axis=1)
    for kk in np.unique(count):
        if kk == 0:
            continue
        sel = np.flatnonzero(count == kk)
        idx = order[sel, :kk]
        sub = a[sel[:, None, None], idx[:, :, None], idx[:, None, :]]
        x[sel[:, None], idx] = _solve_same(sub, np.take_along_axis(b[sel], idx, axis=1))
    return x


def _solve_same(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solutions of a x = b for a stack (G, k, k) of symmetric positive semi-definite systems of one
    size: one stacked LU solve for those whose Cholesky factor exists with a diagonal that is not
    degenerate (there LU and lstsq agree), lstsq's minimum-norm solution one by one for the others.
    Why: LAPACK's SVD-based lstsq costs far more per call on these small systems than a stacked
    Cholesky and LU per system (docs/generation.md#speed); the curve is judged by the exact verdict
    whatever the solve."""
    g = len(a)
    if g == 1:  # one system: the same LAPACK calls on the same matrix, fewer NumPy calls
        x = _solve_one(a, b)
        if x is not None:
            return x
    try:
        low = np.linalg.cholesky(a)
        pd = np.ones(g, bool)
    except np.linalg.LinAlgError:  # some are not positive definite: find which, one by one
        low = np.zeros_like(a)
        pd = np.zeros(g, bool)
        for i in range(g):
            try:
                low[i] = np.linalg.cholesky(a[i : i + 1])[0]
                pd[i] = True
            except np.linalg.LinAlgError:
                pass
    d = np.diagonal(low, axis1=1, axis2=2)
    pd &= np.min(d, axis=1) ** 2 > _PD_RATIO * np.max(d, axis=1) ** 2
    x = np.zeros(b.shape)
    if pd.any():
        x[pd] = np.linalg.solve(a[pd], b[pd][..., None])[..., 0]
    for i in np.flatnonzero(~pd | ~np.all(np.isfinite(x), axis=1)):
        x[i] = np.linalg.lstsq(a[i], b[i], rcond=None)[0]
    return x


def _solve_one(a: np.ndarray, b: np.ndarray):
    """``_solve_same`` of one system (1, k, k) where its Cholesky factor exists, is not degenerate
    and the LU solution is finite (the same factor, test and solve); None otherwise (then
    ``_solve_same``'s general path decides)."""
    try:
        d = np.diagonal(np.linalg.cholesky(a)[0])
    except np.linalg.LinAlgError:
        return None
    lo, hi = float(d.min()), float(d.max())
    if not lo * lo > _PD_RATIO * (hi * hi):
        return None
    x = np.linalg.solve(a, b[..., None])[..., 0]
    return x if np.isfinite(x).all() else None


def _dual(a: np.ndarray, need: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Per row, mu >= 0 minimising 1/2 mu' a mu - need' mu over the ``valid`` constraints (a (G, k, k)
    positive semi-definite, padded past each row's constraints): an active-set solve, every
    constraint active first and the ones whose multiplier comes out negative dropped (mu = 0 for a
    row that does not settle within _ACTIVE_SET_STEPS)."""
    g, k = need.shape
    mu = np.zeros((g, k))
    diag = np.diagonal(a, axis1=1, axis2=2)
    top = np.max(np.where(valid, diag, 0.0), axis=1, keepdims=True)
    # A constraint the spline cannot meet (no freedom along it: a path smoothed to its straight line
    # keeps only the linear modes) gets no multiplier; the verdict then sends the path to the retries.
    act = valid & (diag > _MIN_DIAG * np.maximum(top, 1e-300))
    if g == 1:  # one swing: the same steps without the bookkeeping of rows still to settle
        ac = act
        for _ in range(_ACTIVE_SET_STEPS):
            if not ac.any():
                break
            sol = _solve_stack(a, need, ac)
            if np.all((sol >= 0.0) | ~ac):
                mu[:] = np.where(ac, sol, 0.0)
                break
            ac = ac & (sol > 0.0)
        return mu
    todo = np.arange(g)
    for _ in range(_ACTIVE_SET_STEPS):
        todo = todo[act[todo].any(axis=1)]
        if todo.size == 0:
            break
        ac = act[todo]
        sol = _solve_stack(a[todo], need[todo], ac)
        settled = np.all((sol >= 0.0) | ~ac, axis=1)
        mu[todo[settled]] = np.where(ac[settled], sol[settled], 0.0)
        act[todo] = ac & (sol > 0.0)
        todo = todo[~settled]
    return mu


# m added to the threshold below which clear_rows asks for exact move clearances: a move
# reported at or above the padded threshold has a shortfall below zero however its value rounds.
_BELOW_PAD = 1e-7


class Cleared:
    """One path's correction (``clear_rows``): the curve ``path`` (n, 2), its deviation bound, the
    rounds of correction used, and the clearances its last round measured: ``point_clearance`` (n,)
    and ``move_clearance`` (n-1,), each path's minimum and the move attaining it exact (clear_rows:
    other entries may be lower bounds above the minimum and above the margin; None for a path too short
    for a spline, which is resampled, not corrected)."""

    __slots__ = (
        "path",
        "deviation",
        "rounds",
        "point_clearance",
        "move_clearance",
        "initial",
        "_coef",
        "_ends",
        "_m",
    )

    def __init__(
        self,
        path,
        deviation,
        rounds,
        point_clearance=None,
        move_clearance=None,
        coef=None,
        ends=None,
        m=0,
        initial=None,
    ):
        self.path, self.deviation, self.rounds = path, deviation, rounds
        self.point_clearance, self.move_clearance = point_clearance, move_clearance
        self._coef, self._ends, self._m = coef, ends, m
        # (path, deviation, point clearances, move clearances) of the plain spline, before any
        # correction (the same numbers as smoothing.smooth_candidates' curve of this smoothing),
        # measured like the last round's; None for a path resampled, not smoothed
        self.initial = initial

    def dense(self, dense_points: int) -> np.ndarray:
        """The same curve sampled at ``dense_points`` parameters (for a denser look)."""
        if self._coef is None:
            return sm.linear_resample(self._ends, dense_points)
        out = sm.spline_operators(self._m, dense_points)[2] @ self._coef
        np.maximum(out[:, 1], 0.0, out=out[:, 1])
        out[0], out[-1] = self._ends[0], self._ends[-1]
        return out


def clear_smooth(
    raw: np.ndarray,
    outline: np.ndarray,
    foot_length: float,
    margin: float,
    n_points: int = sm.DEFAULT_POINTS,
    smoothing: float = sm.DEFAULT_SMOOTHING,
    dense_points: int | None = None,
):
    """The smoothed heel path (n_points, 2) of a raw agent path, corrected to keep ``margin`` (m) from
    ``outline`` and to move forward; returns (path, deviation bound m, rounds of correction used), and
    with ``dense_points`` also the same curve sampled at that many parameters (for a denser look)."""
    got = clear_rows([raw], [outline], foot_length, margin, n_points, smoothing)[0]
    if dense_points:
        return got.path, got.deviation, got.rounds, got.dense(int(dense_points))
    return got.path, got.deviation, got.rounds


def _check(raws, outlines, foot_length, margin, n_points, smoothing):
    if len(raws) != len(outlines):
        raise ValueError(f"clear_rows: {len(raws)} raw paths but {len(outlines)} outlines")
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 2:
        raise ValueError(f"n_points must be an integer >= 2, got {n_points!r}")
    for name, v in (("foot_length", foot_length), ("margin", margin), ("smoothing", smoothing)):
        if not np.isfinite(v) or v < 0.0:
            raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
    for i, (raw, outline) in enumerate(zip(raws, outlines)):
        if np.ndim(raw) != 2 or np.shape(raw)[1] != 2 or len(raw) == 0:
            raise ValueError(
                f"raws[{i}]: expected heel points (M, 2) with M >= 1, got shape {np.shape(raw)}"
            )
        if np.ndim(outline) != 2 or np.shape(outline)[1] != 2 or len(outline) < 2:
            raise ValueError(
                f"outlines[{i}]: expected an outline (K, 2) with K >= 2, got shape {np.shape(outline)}"
            )


class _Group:
    """The paths of one point count M (one spline basis): their coefficients (G, M, 2) and the rows
    still being corrected (``alive``, indices into the group)."""

    def __init__(self, m, rows, pts, n_points, smoothing):
        self.m, self.rows = m, np.asarray(rows)
        zm, dm, self.em, self.qm = sm.spline_operators(m, n_points)
        z = np.matmul(zm, pts)  # (G, M, 2)
        lam = sm.solve_lambda(
            np.broadcast_to(dm, (len(rows), m)),
            np.sum(z * z, axis=-1),
            np.full(len(rows), float(smoothing)),
        )
        with np.errstate(invalid="ignore"):
            self.shrink = np.where(
                np.isinf(lam)[:, None],
                (dm == 0.0).astype(float)[None],
                1.0 / (1.0 + lam[:, None] * dm),
            )
        self.zc = z * self.shrink[..., None]
        self.first, self.last = pts[:, 0], pts[:, -1]
        self.alive = np.arange(len(rows))
        self.out = self.dev = (
            None  # the live rows' curves (G, n, 2) and deviation bounds, per round
        )


def clear_rows(
    raws,
    outlines,
    foot_length: float,
    margin: float,
    n_points: int = sm.DEFAULT_POINTS,
    smoothing: float = sm.DEFAULT_SMOOTHING,
    *,
    exact: bool = False,
) -> list[Cleared]:
    """``clear_smooth`` of many raw paths (M_i, 2) on their outlines (K_i, 2): a ``Cleared`` per path.

    Each path's correction is its own; the arithmetic runs on all paths at once: the splines of the
    paths with the same point count in stacked products, the exact clearances in one vectorised call
    per outline size, the dual systems in stacked solves (``_dual``). A move's swept clearance is
    computed exactly only where it can be under the threshold ``margin + SLACK + deviation`` or be
    the path's closest (jaxexo.physics.swept.path_clearance_pruned: the shortfalls that steer the
    correction are the same numbers, and every other move is certainly above the threshold).
    ``exact``: every move's clearance computed exactly (``exact_clear_rows``)."""
    return _clear_rows(raws, outlines, foot_length, margin, n_points, smoothing, exact=exact)


def exact_clear_rows(*args, **kwargs) -> list[Cleared]:
    """``clear_rows`` (the same arguments) with every move's clearance computed exactly: the
    reference it is tested against (the same curves)."""
    return clear_rows(*args, exact=True, **kwargs)


def _clear_rows(
    raws, outlines, foot_length, margin, n_points, smoothing, exact: bool
) -> list[Cleared]:
    """``clear_rows``, every move exact where ``exact``."""
    _check(raws, outlines, foot_length, margin, n_points, smoothing)
    outlines = [np.asarray(o, np.float64) for o in outlines]
    res: list[Cleared | None] = [None] * len(raws)
    by_m: dict[int, list[int]] = {}
    pts_all = []
    for i, raw in enumerate(raws):
        pts = sm.distinct(raw)
        pts_all.append(pts)
        if len(pts) < sm.DEGREE + 1:
            path, dev = sm.linear_resample(pts, n_points, with_deviation=True)
            res[i] = Cleared(path, dev, 0, ends=pts)
        else:
            by_m.setdefault(len(pts), []).append(i)
    groups = [
        _Group(m, rows, np.stack([pts_all[i] for i in rows]), n_points, smoothing)
        for m, rows in by_m.items()
    ]
    h2_8 = (1.0 / (n_points - 1)) ** 2 / 8.0
    sizes = np.array([len(o) for o in outlines])
    # every outline of one size stacked once (k -> (rows of that size, K, 2)), and each row's place in it
    place = np.zeros(len(outlines), np.int64)
    stacks = {}
    for k in np.unique(sizes):
        rows_k = np.flatnonzero(sizes == k)
        place[rows_k] = np.arange(len(rows_k))
        stacks[int(k)] = np.stack([outlines[i] for i in rows_k])
    lib = (sizes, place, stacks)
    for r in range(ROUNDS + 1):
        live = [g for g in groups if g.alive.size]
        if not live:
            break
        for g in live:
            zc = g.zc[g.alive]
            out = np.matmul(g.em, zc)  # (G, n, 2)
            curv = np.max(np.abs(np.matmul(g.qm, zc)), axis=1)  # (G, 2): max |c''| per axis
            g.dev = h2_8 * np.sqrt(np.sum(curv * curv, axis=-1))
            np.maximum(out[..., 1], 0.0, out=out[..., 1])
            out[:, 0], out[:, -1] = g.first[g.alive], g.last[g.alive]
            g.out = out
        out = np.concatenate([g.out for g in live])  # (A, n, 2): every live row
        dev = np.concatenate([g.dev for g in live])
        row = np.concatenate([g.rows[g.alive] for g in live])
        c, sw = _clearances(out, dev, row, lib, foot_length, margin, exact)
        if r == 0:
            initial = {int(i): (out[a], float(dev[a]), c[a], sw[a]) for a, i in enumerate(row)}
        short = margin + SLACK - (sw - dev[:, None])  # (A, n-1)
        fall = out[:, :-1, 0] - out[:, 1:, 0]  # (A, n-1)
        going = ~(((short.max(axis=1) <= 0.0) & (fall.max(axis=1) <= 0.0)) | (r == ROUNDS))
        normal = _normals(out, short, going, row, lib, foot_length) if going.any() else None
        off = 0
        for g in live:
            span = slice(off, off + len(g.alive))
            off += len(g.alive)
            moved = (
                _correct(g, short[span], fall[span], going[span], normal[span], n_points)
                if normal is not None
                else np.zeros(len(g.alive), bool)
            )
            for j, k in enumerate(g.alive):
                if not moved[j]:
                    a = span.start + j
                    i = int(g.rows[k])
                    res[i] = Cleared(
                        out[a], float(dev[a]), r, c[a], sw[a], g.zc[k], pts_all[i], g.m, initial[i]
                    )
            g.alive = g.alive[moved]
    return res


def _clearances(out, dev, row, lib, foot_length, margin, exact):
    """(point clearances (A, n), move clearances (A, n-1)) of the live rows' curves, one call per
    outline size; pruned (``clear_rows``) unless ``exact``."""
    sizes, place, stacks = lib
    a, n = out.shape[:2]
    c = np.empty((a, n))
    sw = np.empty((a, n - 1))
    rs = sizes[row]
    for k in np.unique(rs):
        sel = np.flatnonzero(rs == k)
        ol = stacks[int(k)][place[row[sel]]]
        if exact:
            c[sel] = geometry.foot_clearance(np, out[sel], foot_length, ol[:, None])
            sw[sel] = swept.path_swept_clearance(np, out[sel], foot_length, ol, c[sel])
        else:
            c[sel], sw[sel] = swept.path_clearance_pruned(
                out[sel], foot_length, ol, below=margin + SLACK + dev[sel] + _BELOW_PAD
            )
    return c, sw


def _clear_samples(short, going, n_points):
    """(A, n) the samples that get a clearance constraint: both ends of every move short of the
    margin, the pinned ends excepted, in rows still ``going``."""
    bad = (short > 0.0) & going[:, None]
    s = np.zeros((len(short), n_points), bool)
    s[:, :-1] |= bad
    s[:, 1:] |= bad
    s[:, 0] = s[:, -1] = False  # the pinned ends do not move
    return s


def _normals(out, short, going, row, lib, foot_length):
    """(A, n, 2) outward normals at the constrained samples (zero elsewhere), one foot-clearance call
    per outline size."""
    sizes, place, stacks = lib
    normal = np.zeros(out.shape)
    ra, ia = np.nonzero(_clear_samples(short, going, out.shape[1]))
    if ra.size:
        rs = sizes[row[ra]]
        for k in np.unique(rs):
            sel = np.flatnonzero(rs == k)
            ol = stacks[int(k)][place[row[ra[sel]]]]
            normal[ra[sel], ia[sel]] = _outward(out[ra[sel], ia[sel]], foot_length, ol)
    return normal


def _correct(g, short, fall, going, normal, n_points) -> np.ndarray:
    """One round's correction of group g's live rows (short, fall (G, n-1), going (G,), normal
    (G, n, 2)): their coefficients moved in place; returns (G,) which rows were moved (the others
    are finished: nothing fails, nothing can be done, or the correction would not be a small one)."""
    em, m = g.em, g.m
    moved = going.copy()
    samp = _clear_samples(short, going, n_points)
    back = (fall > 0.0) & going[:, None]
    back[:, n_points - 2 :] = False  # the last sample is pinned
    k_clear = samp.sum(axis=1)
    k = k_clear + back.sum(axis=1)
    moved &= (k > 0) & (k <= MAX_CONSTRAINTS)
    rows = np.flatnonzero(moved)
    if rows.size == 0:
        return moved
    kmax = int(k[rows].max())
    f = np.zeros((len(rows), kmax, m, 2))
    need = np.zeros((len(rows), kmax))
    # clearance constraints first, then the forward ones, each in sample order (one slot each)
    lr, ia = np.nonzero(samp[rows])
    if lr.size:
        slot = np.arange(lr.size) - np.searchsorted(lr, lr)
        s_pad = np.pad(short[rows], ((0, 0), (1, 1)))
        need[lr, slot] = _GROW * np.maximum(np.maximum(s_pad[lr, ia], s_pad[lr, ia + 1]), 0.0)
        f[lr, slot] = em[ia][:, :, None] * normal[rows[lr], ia][:, None, :]
    lb, jb = np.nonzero(back[rows])
    if lb.size:
        slot = k_clear[rows][lb] + np.arange(lb.size) - np.searchsorted(lb, lb)
        need[lb, slot] = _GROW * fall[rows[lb], jb]
        f[lb, slot, :, 0] = em[jb + 1] - em[jb]
    valid = np.arange(kmax)[None, :] < k[rows][:, None]
    live = g.alive[rows]
    fs = f * g.shrink[live][:, None, :, None]
    a = np.einsum("gkmc,glmc->gkl", fs, f)
    mu = _dual(a, need, valid)
    step = np.einsum("gk,gkmc->gmc", mu, fs)
    shift = np.max(np.abs(np.matmul(em, step)), axis=(1, 2))
    ok = np.all(np.isfinite(step), axis=(1, 2)) & (shift <= MAX_SHIFT)
    g.zc[live[ok]] += step[ok]
    moved[rows[~ok]] = False
    return moved
