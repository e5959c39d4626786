"""The footholds' search: the least-cost walk over the foothold grid, a shortest path on the states
(trailing foot, leading foot), and the refusal that says what stops a walk (jaxexo.course, 1.)."""

from __future__ import annotations

import math

import numpy as np

from jaxexo.course.ground import GRID, FootholdRules, describe
from jaxexo.physics import geometry, kinematics


class Planner:
    """The shortest-path search over states (trailing foot a, leading foot b) on the foothold grid;
    a state is stored at [b, b - a]."""

    def __init__(self, r: FootholdRules, ys, valid, obs, lefts, rights):
        self.r, self.ys, self.valid, self.obs = r, ys, valid, obs
        self.n = len(ys)
        self.lo = int(math.ceil(r.lo / GRID - 1e-9))
        self.hi = int(math.floor(r.hi / GRID + 1e-9))
        self.sigma = 0.5 * (self.hi - self.lo) if self.hi > self.lo else 1.0
        # Swing (a, c) covers obstacle j when a < left_j and right_j < c: grid bounds per obstacle.
        self.a_below = np.ceil((lefts - ys[0]) / GRID - 1e-9).astype(np.int64)  # a index < this
        self.c_above = np.floor((rights - ys[0]) / GRID + 1e-9).astype(np.int64)  # c index > this
        sizes = np.array([len(o) for o in obs], np.int64)
        self.too_many = sizes > geometry.MAX_PROFILE_VERTICES - 2
        self.vert_cum = np.concatenate([[0], np.cumsum(sizes)])
        idx = np.arange(self.n)
        self.first_after = np.searchsorted(
            self.a_below, idx, side="right"
        )  # obstacles with a_below > a
        self.last_before = np.searchsorted(
            self.c_above, idx, side="left"
        )  # obstacles with c_above < c
        self.lefts, self.rights = lefts, rights
        self._clear = {}

    def clears(self, j: int) -> tuple[int, np.ndarray]:
        """(k0, ok): whether obstacle j can be cleared with the pivot at grid k0 + i, for the pivots a
        swing over it can have (within the longest step of it), and every pivot within the
        landing tolerance of it."""
        if j in self._clear:
            return self._clear[j]
        r, ob = self.r, self.obs[j]
        k0 = max(0, int(self.c_above[j]) - self.hi)
        k1 = min(self.n, int(self.a_below[j]) + self.hi + 1)
        tol = int(math.ceil(r.tolerance / GRID - 1e-9))
        piv = self.ys[0] + GRID * np.arange(k0 - tol, k1 + tol)
        top = ob[ob[:, 1] > 0.0]
        heels = np.concatenate([top, top - [r.foot, 0.0]]) + [0.0, r.lift]
        hb = np.broadcast_to(heels, (len(piv),) + heels.shape)
        bad = kinematics.swing_heel_unreachable(
            np, piv[:, None], hb, r.thigh, r.shin, r.hip_limits, r.knee_limits
        ).any(axis=1)
        ok = ~bad
        if tol:
            win = np.lib.stride_tricks.sliding_window_view(ok, 2 * tol + 1)
            ok = win.all(axis=1)
        out = (k0, ok[: k1 - k0])
        self._clear[j] = out
        return out

    def _costs(self, b: int, src: np.ndarray, together: bool, last: int | None):
        """Candidate costs from the states (b - d, b) with costs src (H+1,) to (b, b + e): e = 0 only
        (``together``) or e = 1..H; returns (cost (E,), best d (E,))."""
        H = self.hi
        d = np.arange(H + 1)[:, None]
        e = np.array([0]) if together else np.arange(1, H + 1)
        e = e[None, :]
        a, c = b - d, b + e
        s = d + e
        ok = (a >= 0) & (c < self.n) & (s >= self.lo) & (s <= H) & np.isfinite(src)[:, None]
        cc = np.clip(c, 0, self.n - 1)
        ok &= self.valid[cc]
        if together:
            ok &= d > 0
        if not ok.any():
            return np.full(e.shape[1], np.inf), np.zeros(e.shape[1], np.int64)
        aa = np.clip(a, 0, self.n - 1)
        j0, j1 = self.first_after[aa], self.last_before[cc]
        ok &= (
            self.vert_cum[np.maximum(j1, j0)] - self.vert_cum[j0]
            <= geometry.MAX_PROFILE_VERTICES - 2
        )
        lo_j = int(self.first_after[max(b - H, 0)])
        hi_j = int(self.last_before[min(b + H, self.n - 1)])
        for j in range(lo_j, hi_j):
            k0, clear = self.clears(j)
            i = b - k0
            if 0 <= i < len(clear) and clear[i] and not self.too_many[j]:
                continue
            ok &= ~((a < self.a_below[j]) & (c > self.c_above[j]))
        dev = (s - 0.5 * (self.lo + H)) / self.sigma
        piv = (d - e) / (2.0 * self.sigma)
        first = b == 0
        cost = 1.0 + dev * dev + np.where(first | ((c == last) & (e == 0)), 0.0, piv * piv)
        tot = np.where(ok, src[:, None] + cost, np.inf)
        best = np.argmin(tot, axis=0)
        return tot[best, np.arange(tot.shape[1])], best

    def to_goal(self, g: int | None):
        """Grid indices of the landings of the least-cost walk to both feet at g (None: the furthest
        grid point where both feet can stand together; [] when none), or None."""
        H, n = self.hi, self.n
        furthest = g is None
        g = n - 1 if furthest else g
        cost = np.full((n, H + 1), np.inf)
        pred = np.full((n, H + 1), -1, np.int64)
        cost[0, 0] = 0.0
        self.reach = 0
        for b in range(g + 1):
            if not self.valid[b] or not np.isfinite(cost[b]).any():
                continue
            self.reach = b
            if b > 0:
                tc, td = self._costs(b, cost[b], True, g)
                if tc[0] < cost[b, 0]:
                    cost[b, 0], pred[b, 0] = tc[0], td[0]
            if b == g:
                break
            tc, td = self._costs(b, cost[b], False, g)
            for e in np.flatnonzero(np.isfinite(tc)):
                c = b + e + 1
                if c <= g and tc[e] < cost[c, e + 1]:
                    cost[c, e + 1], pred[c, e + 1] = tc[e], td[e]
        if furthest:
            ends = np.flatnonzero(np.isfinite(cost[1:, 0]))
            return self._back(pred, int(ends[-1]) + 1, 0) if ends.size else []
        if not np.isfinite(cost[g, 0]):
            return None
        return self._back(pred, g, 0)

    def _back(self, pred, b, d, layers=None):
        out = []
        k = len(layers) - 1 if layers is not None else None
        while not (b == 0 and d == 0 and (k is None or k == 0)):
            out.append(b)
            p = pred[b, d] if layers is None else layers[k][b, d]
            b, d = b - d, int(p)
            if k is not None:
                k -= 1
        return out[::-1]

    def fixed_steps(self, steps: int):
        """The least-cost walk of exactly ``steps`` swings that ends with the feet together, or None."""
        H, n = self.hi, self.n
        cost = np.full((n, H + 1), np.inf)
        cost[0, 0] = 0.0
        preds = [None]
        self.reach = 0
        for k in range(steps):
            new = np.full((n, H + 1), np.inf)
            pred = np.full((n, H + 1), -1, np.int64)
            final = k == steps - 1
            for b in np.flatnonzero(np.isfinite(cost).any(axis=1)):
                if not self.valid[b]:
                    continue
                self.reach = max(self.reach, int(b))
                tc, td = self._costs(int(b), cost[b], True, int(b) if final else None)
                if tc[0] < new[b, 0]:
                    new[b, 0], pred[b, 0] = tc[0], td[0]
                if final:
                    continue
                tc, td = self._costs(int(b), cost[b], False, None)
                for e in np.flatnonzero(np.isfinite(tc)):
                    c = b + e + 1
                    if tc[e] < new[c, e + 1]:
                        new[c, e + 1], pred[c, e + 1] = tc[e], td[e]
            cost = new
            preds.append(pred)
            if not np.isfinite(cost).any():
                return None
        ends = np.flatnonzero(np.isfinite(cost[:, 0]))
        if not ends.size:
            return None
        g = int(ends[np.argmin(cost[ends, 0])])
        return self._back(None, g, 0, preds)

    def why_not(self, what: str) -> str:
        """The refusal: what stops the walk after the furthest foothold reached."""
        r, y = self.r, float(self.ys[self.reach])
        nxt = np.flatnonzero(self.rights > y)
        if nxt.size:
            j = int(nxt[0])
            ob = self.obs[j]
            need = (ob[-1, 0] - ob[0, 0]) + r.foot + 2.0 * (r.tolerance + r.stand)
            if self.too_many[j]:
                return (
                    f"{what}: {describe(ob)} has {len(ob)} profile points, more than a swing's obstacle "
                    f"may have ({geometry.MAX_PROFILE_VERTICES - 2}); the walk stops at y = {y:.2f} m"
                )
            if need > r.hi + 1e-9:
                return (
                    f"{what}: no step can cross {describe(ob)}: it needs a swing of at least {need:.2f} m "
                    f"(foot and clearances included), longer than the longest step ({r.hi:.2f} m); the walk "
                    f"stops at y = {y:.2f} m"
                )
            k0, clear = self.clears(j)
            if not clear.any():
                return (
                    f"{what}: no swing can clear {describe(ob)}: the heel {r.lift * 100:.1f} cm above it is out "
                    f"of the leg's reach or joint limits for every stance position; the walk stops at "
                    f"y = {y:.2f} m"
                )
        ahead = np.flatnonzero(self.valid[self.reach + 1 :])
        if not ahead.size or ahead[0] + 1 > self.hi:
            gap_to = (
                f"the next is at y = {self.ys[self.reach + 1 + ahead[0]]:.2f} m"
                if ahead.size
                else "there is none"
            )
            return (
                f"{what}: no flat foothold within a step of y = {y:.2f} m ({gap_to}; the longest step is "
                f"{r.hi:.2f} m)"
            )
        ob = describe(self.obs[int(nxt[0])]) if nxt.size else ""
        where = f" across {ob}" if ob and ob not in what else ""
        return (
            f"{what}: the walk gets no further than y = {y:.2f} m: no footholds with swings of "
            f"{r.lo:.2f}-{r.hi:.2f} m lead on from there{where}"
        )
