"""Smoothing that keeps the margin: the thesis's B-spline (thesis 2.7, jaxexo.inference.smoothing),
corrected as little as possible where it comes closer to the obstacle than the margin or moves the
heel backward.

The penalised spline of ``smoothing`` cuts the raw path's corners: with the thesis's s = 0.005 m^2
over ~30 agent points the curve strays about a centimetre from them, and over an obstacle the corners
it cuts are the ones the raw path bends around. Retrying with less smoothing (down to the raw
polyline) keeps the margin but delivers a jagged curve that the joint drives must slow down for.
Here the spline keeps its smoothness and is moved away from the obstacle only where it must be.

For a fixed penalty weight lambda the spline's coefficients a minimise
||W^1/2 (B a - P)||^2 + lambda ||D a||^2 = a' H a - 2 a' B' W P + const (P the agent's points).
A correction da that moves the sampled curve E a by at least ``need_k`` along direction w_k at the
samples of constraint k, at the least cost da' H da, is da = H^-1 sum_k mu_k F_k with F_k = E' w_k
and mu >= 0 the solution of the dual  min 1/2 mu' A mu - need' mu, A_kl = F_k' H^-1 F_l  (an active-set
solve: a few constraints per round). In the Demmler-Reinsch basis of
jaxexo.inference.smoothing, H^-1 is diag(1 / (1 + lambda d)), so A costs a few small products.
Constraints, each round, at the samples that fail:
- clearance: the foot at a sample moves along the outward normal of the foot-obstacle distance (its
  gradient, by central differences) by the shortfall of the exact swept clearance of the moves next
  to it (jaxexo.physics.swept, less the curve's deviation bound), plus ``SLACK``;
- forward motion: where the heel's y falls, the next sample's y is raised to the previous one's.
After ``ROUNDS`` rounds, or as soon as nothing fails, or when a correction would move a sample more
than ``MAX_SHIFT``, the curve is returned with its deviation bound (the same bound as the plain
spline's: jaxexo.inference.smoothing). The result is only a candidate:
the generator's verdict (jaxexo.inference.trajectory) judges it exactly like any other curve, and
a curve that still fails goes through the usual retries.
"""

from __future__ import annotations

import numpy as np

from jaxexo.inference import smoothing as sm
from jaxexo.physics import geometry, swept

ROUNDS = 4
SLACK = 1e-3          # m asked above the margin, so that the next round's curve does not land on it
_GROW = 1.2           # each round asks this multiple of the shortfall (rounding of the normals)
_ACTIVE_SET_STEPS = 8
_NORMAL_EPS = 1e-4    # m, central-difference step of the clearance gradient
_MIN_DIAG = 1e-9      # relative: constraints with less freedom than this are left to the retries
MAX_SHIFT = 0.10      # m: a correction moving a sample further than this is not a small one; not made
# A correction that needs more constraints than this at once (a curve far inside the margin over most
# of its length: seen only on paths that never reach the goal) is not a small one either; not made,
# which also spares a dual system whose solve costs tens of milliseconds.
MAX_CONSTRAINTS = 64


def _outward(path_points, foot_length, outline):
    """Unit outward normals (k, 2) of the foot's distance to the outline at heel points (k, 2)."""
    e = _NORMAL_EPS
    probe = path_points[None, :, :] + np.array([[e, 0.0], [-e, 0.0], [0.0, e], [0.0, -e]])[:, None, :]
    c = geometry.foot_clearance(np, probe.reshape(-1, 2), foot_length, outline[None]).reshape(4, -1)
    g = np.stack([c[0] - c[1], c[2] - c[3]], axis=-1)
    norm = np.linalg.norm(g, axis=-1, keepdims=True)
    return np.where(norm > 0.0, g / np.maximum(norm, 1e-300), [0.0, 1.0])


# Smallest ratio of the Cholesky factor's diagonal entries (squared) for which _solve_psd trusts an
# LU solve; below it the matrix may be nearly singular and lstsq's minimum-norm solution is taken.
_PD_RATIO = 1e-10


def _solve_psd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A solution of a x = b for a small symmetric positive semi-definite a: np.linalg.solve (LU) when
    a's Cholesky factor exists and its diagonal is not degenerate, else lstsq's minimum-norm one.
    Why: LAPACK's SVD-based lstsq costs ~40 us on these 5-30 constraint systems (and far more
    when OpenBLAS's threads compete on a busy machine), LU ~5 us; the two agree wherever a is
    safely positive definite, and the curve is judged by the exact verdict whatever the solve."""
    try:
        low = np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(a, b, rcond=None)[0]
    d = np.diagonal(low)
    if d.min() ** 2 > _PD_RATIO * d.max() ** 2:
        x = np.linalg.solve(a, b)
        if np.all(np.isfinite(x)):
            return x
    return np.linalg.lstsq(a, b, rcond=None)[0]


def _dual(a: np.ndarray, need: np.ndarray) -> np.ndarray:
    """mu >= 0 minimising 1/2 mu' a mu - need' mu (a small, positive semi-definite): an active-set
    solve, every constraint active first and the ones whose multiplier comes out negative dropped."""
    mu = np.zeros(len(need))
    diag = np.diag(a)
    # A constraint the spline cannot meet (no freedom along it: a path smoothed to its straight line
    # keeps only the linear modes) gets no multiplier; the verdict then sends the path to the retries.
    act = np.flatnonzero(diag > _MIN_DIAG * max(float(diag.max()), 1e-300))
    for _ in range(_ACTIVE_SET_STEPS):
        if act.size == 0:
            break
        sol = _solve_psd(a[np.ix_(act, act)], need[act])
        if np.all(sol >= 0.0):
            mu[act] = sol
            break
        act = act[sol > 0.0]
    return mu


# m added to the threshold below which clear_rows asks for exact move clearances (fast): a move
# reported at or above the padded threshold has a shortfall below zero however its value rounds.
_BELOW_PAD = 1e-7


class Cleared:
    """One path's correction (``clear_rows``): the curve ``path`` (n, 2), its deviation bound, the
    rounds of correction used, and the clearances its last round measured: ``point_clearance`` (n,)
    and ``move_clearance`` (n-1,), each path's minimum and the move attaining it exact (fast: other
    entries may be lower bounds above the minimum and above the margin; None for a path too short
    for a spline, which is resampled, not corrected)."""

    __slots__ = ("path", "deviation", "rounds", "point_clearance", "move_clearance", "_coef", "_ends", "_m")

    def __init__(self, path, deviation, rounds, point_clearance=None, move_clearance=None, coef=None, ends=None, m=0):
        self.path, self.deviation, self.rounds = path, deviation, rounds
        self.point_clearance, self.move_clearance = point_clearance, move_clearance
        self._coef, self._ends, self._m = coef, ends, m

    def dense(self, dense_points: int) -> np.ndarray:
        """The same curve sampled at ``dense_points`` parameters (for a denser look)."""
        if self._coef is None:
            return sm.linear_resample(self._ends, dense_points)
        out = sm._basis(self._m, dense_points)[2] @ self._coef
        np.maximum(out[:, 1], 0.0, out=out[:, 1])
        out[0], out[-1] = self._ends[0], self._ends[-1]
        return out


def clear_smooth(raw: np.ndarray, outline: np.ndarray, foot_length: float, margin: float,
                 n_points: int = sm.DEFAULT_POINTS, smoothing: float = sm.DEFAULT_SMOOTHING,
                 dense_points: int | None = None, fast: bool = True):
    """The smoothed heel path (n_points, 2) of a raw agent path, corrected to keep ``margin`` (m) from
    ``outline`` and to move forward; returns (path, deviation bound m, rounds of correction used), and
    with ``dense_points`` also the same curve sampled at that many parameters (for a denser look).
    ``fast``: see ``clear_rows`` (the same curve either way)."""
    got = clear_rows([raw], [outline], foot_length, margin, n_points, smoothing, fast)[0]
    if dense_points:
        return got.path, got.deviation, got.rounds, got.dense(int(dense_points))
    return got.path, got.deviation, got.rounds


class _Row:
    __slots__ = ("pts", "m", "em", "qm", "shrink", "zc", "out", "dev")


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
            raise ValueError(f"raws[{i}]: expected heel points (M, 2) with M >= 1, got shape {np.shape(raw)}")
        if np.ndim(outline) != 2 or np.shape(outline)[1] != 2 or len(outline) < 2:
            raise ValueError(f"outlines[{i}]: expected an outline (K, 2) with K >= 2, got shape {np.shape(outline)}")


def clear_rows(raws, outlines, foot_length: float, margin: float, n_points: int = sm.DEFAULT_POINTS,
               smoothing: float = sm.DEFAULT_SMOOTHING, fast: bool = True) -> list[Cleared]:
    """``clear_smooth`` of many raw paths (M_i, 2) on their outlines (K_i, 2): a ``Cleared`` per path.

    Each path's rounds are its own (the same curve, bit for bit, as on its own: every matrix product
    is the path's own); what is shared is the exact clearance of all paths still being corrected,
    one vectorised call per round and outline size. ``fast`` computes a move's swept clearance
    exactly only where it can be under the threshold ``margin + SLACK + deviation`` or be the
    path's closest (jaxexo.physics.swept.path_clearance_pruned: the shortfalls that steer the
    correction are the same numbers, and every other move is certainly above the threshold);
    ``fast=False`` computes every move exactly (the reference)."""
    _check(raws, outlines, foot_length, margin, n_points, smoothing)
    outlines = [np.asarray(o, np.float64) for o in outlines]
    res: list[Cleared | None] = [None] * len(raws)
    rows: dict[int, _Row] = {}
    for i, raw in enumerate(raws):
        pts = sm.distinct(raw)
        m = len(pts)
        if m < sm.DEGREE + 1:
            path, dev = sm.linear_resample(pts, n_points, with_deviation=True)
            res[i] = Cleared(path, dev, 0, ends=pts)
            continue
        row = rows[i] = _Row()
        zm, dm, row.em, row.qm = sm._basis(m, n_points)
        z = zm @ pts
        lam = sm._solve_lambda(dm[None], np.sum(z * z, axis=-1)[None], np.array([float(smoothing)]))[0]
        row.shrink = (dm == 0.0).astype(float) if np.isinf(lam) else 1.0 / (1.0 + lam * dm)
        row.zc = z * row.shrink[:, None]
        row.pts, row.m = pts, m
    h2_8 = (1.0 / (n_points - 1)) ** 2 / 8.0
    active = list(rows)
    for r in range(ROUNDS + 1):
        if not active:
            break
        for i in active:
            row = rows[i]
            out = row.em @ row.zc
            curv = np.max(np.abs(row.qm @ row.zc), axis=0)
            row.dev = h2_8 * float(np.sqrt(np.sum(curv * curv)))
            np.maximum(out[:, 1], 0.0, out=out[:, 1])
            out[0], out[-1] = row.pts[0], row.pts[-1]
            row.out = out
        clear = _move_clearances([rows[i] for i in active], [outlines[i] for i in active], foot_length,
                                 margin, fast)
        still = []
        for i, (c, sw) in zip(active, clear):
            row = rows[i]
            out, dev = row.out, row.dev
            short = margin + SLACK - (sw - dev)                       # (n-1,)
            fall = out[:-1, 0] - out[1:, 0]                           # (n-1,)
            step = None
            if not ((short.max() <= 0.0 and fall.max() <= 0.0) or r == ROUNDS):
                step = _correction(row, short, fall, outlines[i], foot_length, n_points)
            if step is None:
                res[i] = Cleared(out, dev, r, c, sw, row.zc, row.pts, row.m)
            else:
                row.zc = row.zc + step
                still.append(i)
        active = still
    return res


def _move_clearances(rows, outlines, foot_length, margin, fast):
    """(point clearances (n,), move clearances (n-1,)) of each row's current curve."""
    if not fast:
        out = []
        for row, outline in zip(rows, outlines):
            c = geometry.foot_clearance(np, row.out, foot_length, outline[None])
            out.append((c, swept.path_swept_clearance(np, row.out, foot_length, outline, c)))
        return out
    res = [None] * len(rows)
    by_size: dict[int, list[int]] = {}
    for k, outline in enumerate(outlines):
        by_size.setdefault(len(outline), []).append(k)
    for ks in by_size.values():
        paths = np.stack([rows[k].out for k in ks])
        below = np.array([margin + SLACK + rows[k].dev + _BELOW_PAD for k in ks])
        c, sw = swept.path_clearance_pruned(paths, foot_length, np.stack([outlines[k] for k in ks]), below=below)
        for j, k in enumerate(ks):
            res[k] = (c[j], sw[j])
    return res


def _correction(row, short, fall, outline, foot_length, n_points):
    """The round's change of the coefficients (the dual's solution), or None when there is nothing
    it can do or it would not be a small correction (the curve is then returned as it is)."""
    em, out, m = row.em, row.out, row.m
    rows, needs = [], []
    bad = np.flatnonzero(short > 0.0)
    idx = np.unique(np.concatenate([bad, bad + 1]))
    idx = idx[(idx > 0) & (idx < n_points - 1)]      # the pinned ends do not move
    if idx.size:
        s_pad = np.concatenate([[0.0], short, [0.0]])
        need = _GROW * np.maximum(np.maximum(s_pad[idx], s_pad[idx + 1]), 0.0)
        normal = _outward(out[idx], foot_length, outline)
        rows.append(em[idx][:, :, None] * normal[:, None, :])             # (k, M, 2)
        needs.append(need)
    back = np.flatnonzero(fall > 0.0)
    back = back[back + 1 < n_points - 1]
    if back.size:
        f = np.zeros((len(back), m, 2))
        f[:, :, 0] = em[back + 1] - em[back]
        rows.append(f)
        needs.append(_GROW * fall[back])
    if not rows or sum(len(x) for x in needs) > MAX_CONSTRAINTS:
        return None
    f = np.concatenate(rows)
    need = np.concatenate(needs)
    fs = f * row.shrink[None, :, None]
    a = np.einsum("kmc,lmc->kl", fs, f)
    mu = _dual(a, need)
    step = np.einsum("k,kmc->mc", mu, fs)
    if not np.all(np.isfinite(step)) or np.max(np.abs(em @ step)) > MAX_SHIFT:
        return None
    return step
