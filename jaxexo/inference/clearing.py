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


def _outward(path_points, foot_length, outline):
    """Unit outward normals (k, 2) of the foot's distance to the outline at heel points (k, 2)."""
    e = _NORMAL_EPS
    probe = path_points[None, :, :] + np.array([[e, 0.0], [-e, 0.0], [0.0, e], [0.0, -e]])[:, None, :]
    c = geometry.foot_clearance(np, probe.reshape(-1, 2), foot_length, outline[None]).reshape(4, -1)
    g = np.stack([c[0] - c[1], c[2] - c[3]], axis=-1)
    norm = np.linalg.norm(g, axis=-1, keepdims=True)
    return np.where(norm > 0.0, g / np.maximum(norm, 1e-300), [0.0, 1.0])


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
        sol = np.linalg.lstsq(a[np.ix_(act, act)], need[act], rcond=None)[0]
        if np.all(sol >= 0.0):
            mu[act] = sol
            break
        act = act[sol > 0.0]
    return mu


def clear_smooth(raw: np.ndarray, outline: np.ndarray, foot_length: float, margin: float,
                 n_points: int = sm.DEFAULT_POINTS, smoothing: float = sm.DEFAULT_SMOOTHING,
                 dense_points: int | None = None):
    """The smoothed heel path (n_points, 2) of a raw agent path, corrected to keep ``margin`` (m) from
    ``outline`` and to move forward; returns (path, deviation bound m, rounds of correction used), and
    with ``dense_points`` also the same curve sampled at that many parameters (for a denser look)."""
    pts = sm.distinct(raw)
    m = len(pts)
    if m < sm.DEGREE + 1:
        path, dev = sm.linear_resample(pts, n_points, with_deviation=True)
        if dense_points:
            return path, dev, 0, sm.linear_resample(pts, dense_points)
        return path, dev, 0
    zm, dm, em, qm = sm._basis(m, n_points)
    z = zm @ pts
    lam = sm._solve_lambda(dm[None], np.sum(z * z, axis=-1)[None], np.array([float(smoothing)]))[0]
    shrink = (dm == 0.0).astype(float) if np.isinf(lam) else 1.0 / (1.0 + lam * dm)
    zc = z * shrink[:, None]
    h2_8 = (1.0 / (n_points - 1)) ** 2 / 8.0
    for r in range(ROUNDS + 1):
        out = em @ zc
        curv = np.max(np.abs(qm @ zc), axis=0)
        dev = h2_8 * float(np.sqrt(np.sum(curv * curv)))
        np.maximum(out[:, 1], 0.0, out=out[:, 1])
        out[0], out[-1] = pts[0], pts[-1]
        short = margin + SLACK - (swept.path_swept_clearance(np, out, foot_length, outline) - dev)   # (n-1,)
        fall = out[:-1, 0] - out[1:, 0]                                                               # (n-1,)
        if (short.max() <= 0.0 and fall.max() <= 0.0) or r == ROUNDS:
            return _result(out, dev, r, zc, pts, m, dense_points)
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
        if not rows:
            return _result(out, dev, r, zc, pts, m, dense_points)
        f = np.concatenate(rows)
        need = np.concatenate(needs)
        fs = f * shrink[None, :, None]
        a = np.einsum("kmc,lmc->kl", fs, f)
        mu = _dual(a, need)
        step = np.einsum("k,kmc->mc", mu, fs)
        if not np.all(np.isfinite(step)) or np.max(np.abs(em @ step)) > MAX_SHIFT:
            return _result(out, dev, r, zc, pts, m, dense_points)
        zc = zc + step
    raise AssertionError("unreachable: the last round returns")


def _result(out, dev, rounds, zc, pts, m, dense_points):
    if not dense_points:
        return out, dev, rounds
    dense = sm._basis(m, dense_points)[2] @ zc
    np.maximum(dense[:, 1], 0.0, out=dense[:, 1])
    dense[0], dense[-1] = pts[0], pts[-1]
    return out, dev, rounds, dense
