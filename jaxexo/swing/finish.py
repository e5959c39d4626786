"""Finish a path: a generator's raw heel points landed on the floor (``landed``), smoothed (thesis
2.7), checked, and retried in order (the corrected spline, the per-path candidate smoothings, less
smoothing, the raw polyline) until a curve keeps the margin. ``PathFinisher(exact=True)`` is the
plain reference that the fast path is tested against. Method: docs/generation.md (the landing;
smoothing and correction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxexo.physics import transition
from jaxexo.swing import smoothing as sm
from jaxexo.swing import trajectory
from jaxexo.swing.clearing import clear_rows, exact_clear_rows
from jaxexo.swing.trajectory import TrajectoryBatch, assemble

# Per-path candidate smoothings: s = M * rho^2 for these rho (m), a root-mean-square residual of rho
# per point. A shielded raw path keeps env.shield_clearance, 5 mm above the verdict's margin; the
# thesis's s (an RMS residual of ~1 cm on a 30-point path) cuts its corners by more than that, much
# smaller ones wiggle the heel back (what these four rescue: docs/generation.md, smoothing).
CANDIDATE_RESIDUALS = (0.008, 0.005, 0.004, 0.0025)

# Smoothing multipliers tried last, before the raw polyline.
RETRY_FACTORS = (0.25, 1.0 / 16.0, 0.0)

# m a retried curve must keep above the margin to be accepted (the verdict itself asks for none): the
# device-ready swing (jaxexo.swing.timing) resamples a C1 interpolant of the samples, which
# can pass a little closer than their polyline (docs/generation.md, smoothing); with this much to
# spare it keeps the margin when timed. The raw polyline keeps the shield's 5 mm in any case.
ACCEPT_HEADROOM = 5e-4

CLEARED_NOTE = (
    "the spline of smoothing {s:g} m^2 is corrected where it came within the safety margin or "
    "moved the heel back (jaxexo.swing.clearing)"
)


@dataclass(frozen=True)
class _Retry:
    """One row's chosen or retried curve: its path (N, 2), the smoothing used (m^2; nan: the raw
    polyline), notes, deviation bound (m) and, where a check or its correction measured them, its
    (point, move) clearances."""

    path: np.ndarray
    smoothing: float
    notes: tuple
    deviation: float
    clearances: tuple | None = None


@dataclass(frozen=True)
class _Chosen:
    """The curves chosen for B rows: paths (B, N, 2), deviation bounds (B,), smoothings and notes
    per row, and ``measure``'s record of them when already known (None: assemble measures)."""

    paths: np.ndarray
    deviation: np.ndarray
    smoothing: list
    notes: list
    measured: trajectory.Measured | None


def landed(sp, raw: np.ndarray, goal_y: float) -> np.ndarray:
    """The raw path (M, 2) with its landing (docs/generation.md, the landing): unchanged when it ends on the floor or
    short of the goal (that swing fails its verdict however it ends); otherwise one more point on the
    floor, on the line of the last move when that move descends and the point is in the goal box,
    else straight below the end (in the box, as the end is)."""
    raw = np.asarray(raw, dtype=np.float64)
    y, z = float(raw[-1, 0]), float(raw[-1, 1])
    if z <= 0.0 or not transition.goal_reached(np, sp, y, z, goal_y):
        return raw
    land = y
    if len(raw) > 1:
        dy, dz = raw[-1] - raw[-2]
        # continuing the last move keeps the direction the policy came down in (no corner to smooth)
        if dz < 0.0 and dy > 0.0 and transition.goal_reached(np, sp, y + z * dy / -dz, 0.0, goal_y):
            land = y + z * dy / -dz
    return np.vstack([raw, [[land, 0.0]]])


def candidates(raw, smoothing: float) -> list[float]:
    """The smoothings tried in one pass, smoothest first: ``smoothing`` and the smaller per-path
    M * rho^2 of CANDIDATE_RESIDUALS (paths of fewer than 4 points are not smoothed: one)."""
    m = len(sm.distinct(raw))
    out = [float(smoothing)]
    if m < sm.DEGREE + 1:
        return out
    for rho in CANDIDATE_RESIDUALS:
        c = m * rho * rho
        if c < out[-1]:
            out.append(c)
    return out


def _candidate_note(smoothing, used):
    return (
        f"smoothing {smoothing:g} m^2 would bring the foot within the safety margin or move the heel "
        f"back; the per-path candidate {used:g} m^2 is used",
    )


def _first_passing(paths, dev, ok, smoothing: float, cands, clearances) -> _Retry:
    """The first of one swing's candidates ``paths`` (C, N, 2) that passes (``ok``: the first ones'),
    else the requested one (the first); ``clearances``: (point, move), None: not measured."""
    j = int(np.argmax(ok)) if ok.any() else 0
    clear = None if clearances is None else (clearances[0][j], clearances[1][j])
    return _Retry(
        paths[j], cands[j], _candidate_note(smoothing, cands[j]) if j else (), dev[j], clear
    )


class PathFinisher:
    """Smooth, check and retry raw paths for the constants ``sp`` (jaxexo.config.scalar_params,
    at the swing's clearance); ``clearing``: try the corrected spline first;
    ``exact``: the plain reference (every move exact, each curve measured afresh), which the fast path is tested against."""

    def __init__(self, sp, clearing: bool = True, exact: bool = False):
        self.sp, self.clearing, self.exact = sp, clearing, exact
        self._clearances = trajectory.exact_path_clearances if exact else trajectory.path_clearances
        self._clear_rows = exact_clear_rows if exact else clear_rows

    def margin_ok(
        self,
        scenes,
        paths: np.ndarray,
        deviation,
        headroom: float = ACCEPT_HEADROOM,
        with_clearances: bool = False,
    ):
        """``trajectory.passes`` of curves (B, N, 2) with deviation bounds (B,); with ``with_clearances``
        also their point and move clearances (``trajectory.path_clearances``, ``measure``'s inputs)."""
        deviation = np.asarray(deviation, np.float64)
        c, sw = self._clearances(self.sp.foot_length, paths, scenes)
        ok = trajectory.passes(
            self.sp,
            trajectory.lowest_clearance(c, sw),
            deviation,
            trajectory.backward_bound(paths, deviation),
            headroom,
        )
        return (ok, c, sw) if with_clearances else ok

    def _measured(self, scene, path, c, sw, dev):
        """trajectory.measure of one scene's path (1, N, 2) from its clearances, for assemble."""
        return trajectory.measure(
            self.sp, path, c, np.array([scene.pivot_y]), np.array([scene.goal_y]), sw, dev
        )

    def _best_candidate(self, scene, paths, dev, checked, smoothing: float, cands) -> _Retry:
        """``_first_passing`` from the first candidates' check (ok, point and move clearances or
        None): the others checked together where the requested one fails."""
        ok, c, sw = checked
        if not ok[0] and len(ok) < len(paths):
            rest = self.margin_ok(
                [scene] * (len(paths) - 1), paths[1:], dev[1:], with_clearances=True
            )
            ok, c, sw = (np.concatenate(x) for x in zip((ok, c, sw), rest))
        return _first_passing(paths, dev, ok, smoothing, cands, None if c is None else (c, sw))

    def _one_pass(self, scene, raw, n_points: int, smoothing: float) -> _Chosen:
        """One swing's candidates smoothed together (smoothing.smooth_candidates); the first that passes
        is used (the requested smoothing when none does: the retries then follow), except that the
        requested spline corrected comes before the other candidates when the requested one fails.
        The fast path checks the requested smoothing first (through the correction's first round,
        which measures that very spline, where it does), then the correction, and the other
        candidates only when both fail. Returns the chosen curve (_Chosen, one row)."""
        cands = candidates(raw, smoothing)
        chosen = None
        if not self.exact and self.clearing:
            chosen = self._through_correction(scene, raw, n_points, smoothing, cands)
        if chosen is None:
            chosen = self._requested_first(scene, raw, n_points, smoothing, cands)
        return self._chosen_one(scene, chosen)

    def _through_correction(self, scene, raw, n_points: int, smoothing: float, cands):
        """The fast path where the correction's first round measured the requested spline: that
        spline if it passes, else its correction if that passes, else the first other candidate
        that passes (_Retry); None where the first round measured no spline."""
        sp = self.sp
        got = clear_rows(
            [raw], [scene.outline], sp.foot_length, sp.min_clearance, n_points, smoothing
        )[0]
        if got.initial is None:
            return None
        p0, d0, c0, sw0 = got.initial
        if trajectory.passes(sp, sw0.min(), d0, trajectory.backward_bound(p0, d0), ACCEPT_HEADROOM):
            return _Retry(p0, cands[0], (), d0, (c0, sw0))
        cleared = self._judge_cleared([scene], [0], [got], smoothing)
        if cleared:
            return cleared[0][1]
        paths, dev = sm.smooth_candidates(raw, n_points, cands)
        checked = (np.zeros(1, bool), c0[None], sw0[None])
        return self._best_candidate(scene, paths, dev, checked, smoothing, cands)

    def _requested_first(self, scene, raw, n_points: int, smoothing: float, cands):
        """The requested spline checked (the fast path: alone, with its clearances; the reference:
        with every candidate), then its correction where it fails, then the other candidates
        (_Retry)."""
        paths, dev = sm.smooth_candidates(raw, n_points, cands)
        if self.exact:
            checked = (self.margin_ok([scene] * len(cands), paths, dev), None, None)
        else:
            checked = self.margin_ok([scene], paths[:1], dev[:1], with_clearances=True)
        ok = checked[0][0]
        cleared = [] if ok else self._cleared_rows([scene], [raw], [0], n_points, smoothing)
        if cleared:
            return cleared[0][1]
        return self._best_candidate(scene, paths, dev, checked, smoothing, cands)

    def _chosen_one(self, scene, r: _Retry) -> _Chosen:
        """One swing's chosen curve ``r``, measured from its clearances when known."""
        measured = None
        if r.clearances is not None:
            c, sw = r.clearances
            measured = self._measured(
                scene, r.path[None], c[None], sw[None], np.array([r.deviation])
            )
        return _Chosen(r.path[None], np.array([r.deviation]), [r.smoothing], [r.notes], measured)

    def _cleared_rows(self, scenes, raws, rows, n_points: int, smoothing: float):
        """Rows whose requested smoothing failed: the requested spline corrected (jaxexo.swing.clearing,
        all rows' rounds together), as (row, _Retry) for the
        rows whose corrected curve passes (``_judge_cleared``)."""
        if not self.clearing or len(rows) == 0:
            return []
        rows = [int(i) for i in rows]
        got = self._clear_rows(
            [raws[i] for i in rows],
            [scenes[i].outline for i in rows],
            self.sp.foot_length,
            self.sp.min_clearance,
            n_points,
            smoothing,
        )
        return self._judge_cleared(scenes, rows, got, smoothing)

    def _judge_cleared(self, scenes, rows, got, smoothing: float):
        """The verdict on the corrections ``got`` (clearing.Cleared) of rows ``rows``. The fast path
        judges each curve on the clearances the correction's last round measured and returns them as
        (point, move) clearances for assemble (None where the path was resampled, not corrected);
        the reference measures each curve afresh, every move exact."""
        paths = np.stack([g.path for g in got])
        dev = np.array([g.deviation for g in got], np.float64)
        if not self.exact:
            ok = np.zeros(len(rows), bool)
            have = [
                k
                for k, g in enumerate(got)
                if g.move_clearance is not None and g.move_clearance.size
            ]
            if have:
                low = np.array([got[k].move_clearance.min() for k in have])
                ok[have] = trajectory.passes(
                    self.sp,
                    low,
                    dev[have],
                    trajectory.backward_bound(paths[have], dev[have]),
                    ACCEPT_HEADROOM,
                )
            known = set(have)
            rest = [k for k in range(len(rows)) if k not in known]
            if rest:
                ok[rest] = self.margin_ok([scenes[rows[k]] for k in rest], paths[rest], dev[rest])
            clear = [
                None if g.move_clearance is None else (g.point_clearance, g.move_clearance)
                for g in got
            ]
        else:
            ok = self.margin_ok([scenes[i] for i in rows], paths, dev)
            clear = [None] * len(rows)
        note = (CLEARED_NOTE.format(s=smoothing),)
        return [
            (i, _Retry(paths[k], float(smoothing), note, dev[k], clear[k]))
            for k, i in enumerate(rows)
            if ok[k]
        ]

    def _candidate_rows(self, scenes, raws, rows, n_points: int, smoothing: float):
        """Rows whose requested smoothing failed: the first of their other candidates that passes, as
        (row, _Retry). One swing: all its candidates smoothed in one call;
        many: candidate by candidate over the rows still failing, each level in one call."""
        cands = {int(i): candidates(raws[i], smoothing)[1:] for i in rows}
        out = {}
        wait = [i for i in cands if cands[i]]
        level = 0
        while wait:
            if len(scenes) == 1:
                pairs = [(i, c) for i in wait for c in cands[i]]
            else:
                pairs = [(i, cands[i][level]) for i in wait]
            paths, dev = sm.smooth_paths(
                [raws[i] for i, _ in pairs],
                n_points,
                np.array([c for _, c in pairs]),
                with_deviation=True,
            )
            ok = self.margin_ok([scenes[i] for i, _ in pairs], paths, dev)
            for k, (i, c) in enumerate(pairs):
                if ok[k] and i not in out:
                    out[i] = _Retry(paths[k], c, _candidate_note(smoothing, c), dev[k])
            level += 1
            wait = (
                []
                if len(scenes) == 1
                else [i for i in wait if i not in out and level < len(cands[i])]
            )
        return sorted(out.items())

    def _less_smoothing(self, scenes, raws, rows, n_points: int, smoothing: float):
        """The last retries of rows ``rows``: when the raw path keeps the margin, less smoothing
        (RETRY_FACTORS), then the raw polyline; each factor's curves of all rows still waiting checked
        in one call. Returns (row, _Retry) in row order; a row whose
        raw path breaks the margin is left out (its smoothing is kept and the checks report it)."""
        pts = [sm.distinct(raws[i]) for i in rows]
        zero = np.zeros(len(rows))
        if not self.exact:
            # Raw paths padded with their last point (a repeated point adds a zero-length move, whose
            # swept clearance is that point's own: the polyline's minimum is unchanged).
            n = max(len(p) for p in pts)
            padded = np.stack(
                [np.concatenate([p, np.repeat(p[-1:], n - len(p), axis=0)]) for p in pts]
            )
            keeps = self.margin_ok([scenes[i] for i in rows], padded, zero, headroom=0.0)
        else:
            keeps = [
                self.margin_ok([scenes[i]], p[None], zero[:1], headroom=0.0)[0]
                for i, p in zip(rows, pts)
            ]
        wait = [
            j for j, ok in enumerate(keeps) if ok or len(pts[j]) == 1
        ]  # one point: no move to check
        out = {}
        for f in RETRY_FACTORS:
            if not wait:
                break
            # each row smoothed on its own (a straight leg's joint angles amplify a last-bit difference
            # in the samples to ~1e-8 rad); the checks are vectorised
            one = [
                sm.smooth_paths([raws[rows[j]]], n_points, smoothing * f, with_deviation=True)
                for j in wait
            ]
            cand, dev = np.concatenate([c for c, _ in one]), np.concatenate([d for _, d in one])
            ok = self.margin_ok([scenes[rows[j]] for j in wait], cand, dev)
            for k, j in enumerate(wait):
                if ok[k]:
                    note = (
                        f"smoothing {smoothing:g} m^2 brought the foot within the safety margin or moved the "
                        f"heel back; {smoothing * f:g} m^2 used",
                    )
                    out[j] = _Retry(cand[k], smoothing * f, note, dev[k])
            wait = [j for k, j in enumerate(wait) if not ok[k]]
        for j in wait:
            path, dev = sm.linear_resample(raws[rows[j]], n_points, with_deviation=True)
            out[j] = _Retry(
                path,
                float("nan"),
                (
                    "every smoothing brought the foot within the safety margin or moved the heel back; the raw "
                    "polyline is used",
                ),
                dev,
            )
        return [(int(rows[j]), out[j]) for j in sorted(out)]

    def _many(self, scenes, raws, paths, dev, n_points: int, smoothing: float):
        """Many swings smoothed with ``smoothing``: the requested curves checked at once, then the rows
        they fail retried (corrected spline, then candidates level by level): the chosen curves."""
        used = [smoothing] * len(raws)
        notes = [()] * len(raws)
        if not self.exact:
            ok, c_all, sw_all = self.margin_ok(scenes, paths, dev, with_clearances=True)
        else:
            ok = self.margin_ok(scenes, paths, dev)
        cleared = self._cleared_rows(scenes, raws, np.flatnonzero(~ok), n_points, smoothing)
        done = {i for i, _ in cleared}
        redo = list(cleared) + self._candidate_rows(
            scenes, raws, [i for i in np.flatnonzero(~ok) if i not in done], n_points, smoothing
        )
        if redo:
            paths, dev, notes = paths.copy(), np.array(dev, np.float64), list(notes)
            for i, r in redo:
                paths[i], dev[i], used[i], notes[i] = r.path, r.deviation, r.smoothing, r.notes
        if self.exact:
            return _Chosen(paths, dev, used, notes, None)
        # assemble measures from the clearances already computed: the requested smoothing's (each
        # path's closest move exact), the corrected curves' own; the rest afresh
        known = {i for i, r in cleared if r.clearances is not None}
        for i, r in cleared:
            if r.clearances is not None:
                c_all[i], sw_all[i] = r.clearances
        fresh = sorted({i for i, _ in redo} - known)
        if fresh:
            _, c_all[fresh], sw_all[fresh] = self.margin_ok(
                [scenes[i] for i in fresh], paths[fresh], dev[fresh], with_clearances=True
            )
        measured = trajectory.measure(
            self.sp,
            paths,
            c_all,
            np.array([sc.pivot_y for sc in scenes]),
            np.array([sc.goal_y for sc in scenes]),
            sw_all,
            dev,
        )
        return _Chosen(paths, dev, used, notes, measured)

    def _measure(self, scenes, paths, deviation) -> trajectory.Measured:
        """``trajectory.measure_paths`` of curves on their scenes with this finisher's clearances."""
        paths = np.asarray(paths, dtype=np.float64)  # as assemble reads them
        return trajectory.measure_paths(
            self.sp, paths, scenes, deviation, self._clearances(self.sp.foot_length, paths, scenes)
        )

    def finish(
        self, method: str, scenes, raws, n_points: int, smoothing: float, duration: float
    ) -> TrajectoryBatch:
        """Checked trajectories of raw paths (M_i, 2) on their scenes: smoothed with ``smoothing`` (m^2; 0:
        the raw polylines resampled), checked, and retried where a curve fails but its raw path
        need not (docs/generation.md). Each raw path lands first (``landed``); the trajectories' ``raw``
        hold the landed paths."""
        raws = [landed(self.sp, r, sc.goal_y) for r, sc in zip(raws, scenes)]
        if smoothing > 0 and len(raws) == 1 and len(candidates(raws[0], smoothing)) > 1:
            got = self._one_pass(scenes[0], raws[0], n_points, smoothing)
        elif smoothing > 0:
            paths, dev = sm.smooth_paths(raws, n_points, smoothing, with_deviation=True)
            got = _Chosen(paths, dev, [smoothing] * len(raws), [()] * len(raws), None)
            if len(raws) > 1:
                got = self._many(scenes, raws, paths, dev, n_points, smoothing)
        else:
            both = [sm.linear_resample(r, n_points, with_deviation=True) for r in raws]
            paths, dev = np.stack([p for p, _ in both]), np.array([d for _, d in both])
            got = _Chosen(paths, dev, [float("nan")] * len(raws), [()] * len(raws), None)
        batch = assemble(
            method,
            self.sp,
            scenes,
            raws,
            got.paths,
            got.smoothing,
            duration,
            got.notes,
            got.measured
            if got.measured is not None
            else self._measure(scenes, got.paths, got.deviation),
        )
        # Not for a swing that ends short of the goal: every curve ends where its raw path does, so no
        # smoothing can make it pass (the policy's failure, not the smoothing's).
        if smoothing <= 0:
            return batch
        bad = np.flatnonzero(
            (~batch.clearance_ok | (batch.heel_backward > self.sp.backward_tolerance))
            & batch.reached_goal
        )
        redo = self._less_smoothing(scenes, raws, bad, n_points, smoothing) if bad.size else []
        if not redo:
            return batch
        idx = [i for i, _ in redo]
        sub_scenes, sub_paths = [scenes[i] for i in idx], np.stack([r.path for _, r in redo])
        sub = assemble(
            method,
            self.sp,
            sub_scenes,
            [raws[i] for i in idx],
            sub_paths,
            [r.smoothing for _, r in redo],
            duration,
            [r.notes for _, r in redo],
            self._measure(sub_scenes, sub_paths, np.array([r.deviation for _, r in redo])),
        )
        return batch.with_rows(idx, sub)
