"""The check on a timed swing's curve: a time law's curve at its check times (``with_checks``),
the passes' caps lowered where it exceeds a limit (``lowered_cap``), and the final law, slowed
uniformly to the limits, the minimum duration and whole control periods (``final_law``). Used by
jaxexo.swing.timing; the method: docs/device-timing.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from jaxexo.config import MAX_SWING_DURATION
from jaxexo.swing.curve import JointPath, TimeLaw, joints_at, laws_at
from jaxexo.swing.limits import DeviceLimits, GridView, peak_ratio

CHECK_MARGIN = 5e-3  # the curve must stay within (1 - this) of each limit at the check times
CHECK_DT = 1e-3  # s: spacing of the check times (with every breakpoint of the time law) ...
CHECK_PER_NODE = 16  # ... at most this many per node of the law
LOCAL_SLOWEST = 10.0  # a local correction slows a stretch by at most this factor
BYTES_PER_SAMPLE = 1024  # twice what timing holds per exported sample (docs/reliability.md)


def max_samples() -> int:
    """The most samples one timed swing may have: half the memory this process may still use
    (jaxexo.config.memory.process_memory_bytes: the machine's available memory, ``ulimit -v`` and
    the cgroup's limit) at BYTES_PER_SAMPLE, and at least 100,000 (10 s at 10 kHz)
    where that many fit."""
    from jaxexo.config.memory import process_memory_bytes

    room = process_memory_bytes()
    return max(min(100_000, room // BYTES_PER_SAMPLE), room // 2 // BYTES_PER_SAMPLE)


@dataclass(frozen=True)
class Plan:
    """One swing's timing state: its joint path, the passes' grid and caps, the law."""

    path: JointPath
    view: GridView  # B = 1
    cap: np.ndarray  # (K,) caps on s'^2 from the local corrections
    x: np.ndarray  # (K,) the passes' s'^2
    law: TimeLaw | None
    check: "CurveCheck | None" = None


@dataclass(frozen=True)
class CurveCheck:
    """A law's curve at its check times t (n,): s (n,), [q, q-dot, q-ddot, q-dddot] (n, J), and
    the peaks of |q-dot|, |q-ddot|, |q-dddot| over the times (J,) each."""

    t: np.ndarray
    s: np.ndarray
    derivs: tuple
    peaks: tuple


def column_max(a: np.ndarray) -> np.ndarray:
    """``a.max(axis=0)`` of a tall (n, J) array, column by column: the same values, several times
    faster than NumPy's reduction across a short row."""
    return np.array([a[:, j].max() for j in range(a.shape[1])])


def check_times(paths, laws) -> list[tuple[np.ndarray, tuple]]:
    """Where each curve is checked: every CHECK_DT, and both sides of every breakpoint of the law
    and of every knot of the path (where the jerk may jump), so that between check times the
    velocity, acceleration and jerk are smooth and their maxima are caught to second order. Per
    curve: the times, sorted, and the law's four values there (``laws_at``; the grid's are those
    the knots were placed with: a time's values depend on it alone)."""
    # At most CHECK_PER_NODE points per node of the law: a very slow law (limits near zero, a
    # path that nearly stops) is checked as finely relative to its own pieces, in bounded memory.
    grids = [
        np.linspace(
            0.0,
            law.duration,
            max(
                2, min(int(math.ceil(law.duration / CHECK_DT)), CHECK_PER_NODE * len(law.nodes)) + 1
            ),
        )
        for law in laws
    ]
    on_grid = laws_at(laws, grids)
    sides = []
    for path, law, grid, lv in zip(paths, laws, grids, on_grid):
        d = law.duration
        knots = np.interp(path.knots[1:-1], lv[0], grid)
        b = np.concatenate([law.breakpoints(), knots])
        eps = 1e-9 * max(d, 1e-9)
        sides.append(np.clip(np.concatenate([b - eps, b + eps]), 0.0, d))
    out = []
    # The grid lies in [0, duration] (linspace ends on it exactly): clipped, it is itself.
    for grid, side, lg, ls in zip(grids, sides, on_grid, laws_at(laws, sides)):
        t = np.concatenate([grid, side])
        order = np.argsort(t, kind="stable")
        out.append((t[order], tuple(np.concatenate([x, y])[order] for x, y in zip(lg, ls))))
    return out


def with_checks(plans, idx) -> list[Plan]:
    """plans[idx] with their curves evaluated at their check times, one curve at a time: a batch
    checks each curve exactly as it is checked alone (batch = single by construction), and a
    curve's few thousand check times stay in cache (the batch's stacked evaluation took twice
    as long per curve)."""
    plans = list(plans)
    for i in idx:
        p = plans[i]
        ((t, values),) = check_times([p.path], [p.law])
        ((s, derivs),) = joints_at([p.path], [p.law], [t], [values])
        peaks = tuple(column_max(np.abs(d)) for d in derivs[1:])
        plans[i] = replace(p, check=CurveCheck(t, s, tuple(derivs), peaks))
    return plans


def lowered_cap(p: Plan, ratio, s, t) -> np.ndarray:
    """Where the curve exceeds a limit, the passes' cap on s'^2 lowered by the excess over the
    stretch of s the law's window averages there (one window either side)."""
    cap = p.cap.copy()
    bad = np.flatnonzero(ratio > 1.0)
    w = p.law.window
    grid = p.view.s
    # Per point over a limit, the grid cells [lo, hi) its window reaches. The times are sorted and
    # s(t) never decreases, so lo and hi never decrease from one point to the next.
    lo = np.searchsorted(grid, np.interp(t[bad] - w, t, s), side="left") - 1
    hi = np.searchsorted(grid, np.interp(t[bad] + w, t, s), side="right") + 1
    lo, hi = np.maximum(lo, 0), np.minimum(hi, len(grid))
    # At most LOCAL_SLOWEST slower per pass: a point far over a limit (a degenerate path) is left
    # to the uniform slow-down, which is bounded, rather than crawled through at no speed.
    factor = (1.0 / np.minimum(ratio[bad], LOCAL_SLOWEST)) ** 2
    # A cell's points are then a run of them: those with lo <= cell < hi, [first, last). The least
    # factor of each run by a range-minimum table: linear in the points and cells, where listing
    # every (point, cell) pair grew with their product (a wandering swing: 0.4 s a call).
    cells = np.arange(len(grid))
    first = np.searchsorted(hi, cells, side="right")
    last = np.searchsorted(lo, cells, side="right")
    hit = np.flatnonzero(first < last)
    least = _range_min(factor, first[hit], last[hit])
    # Where the passes already stop (s'^2 = 0: the rest ends, a cusp) a lower cap changes nothing
    # but the floor of the cells around it, which would then be crossed at no speed. x * least is
    # the least of x * factor (x >= 0: a product's rounding keeps the order).
    x = p.x[hit]
    moving = x > 0.0
    cells = hit[moving]
    cap[cells] = np.minimum(cap[cells], x[moving] * least[moving])
    return cap


def _range_min(f: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """min(f[a_k:b_k]) for each k (a_k < b_k): a sparse table of minima over spans of 2^j."""
    levels = [f]
    while 2 * (span := 1 << (len(levels) - 1)) <= len(f):
        prev = levels[-1]
        levels.append(np.minimum(prev[:-span], prev[span:]))
    k = np.frexp((b - a).astype(np.float64))[1] - 1  # floor(log2(b - a)), exactly
    out = np.empty(len(a))
    for j in np.unique(k):
        sel = np.flatnonzero(k == j)
        lv = levels[j]
        out[sel] = np.minimum(lv[a[sel]], lv[b[sel] - (1 << int(j))])
    return out


@dataclass(frozen=True)
class FinalLaw:
    """A swing's final law: the passes' law slowed by ``scale`` (the uniform slow-down ``slow``,
    the minimum duration, whole control periods), and the curve's peaks under it."""

    law: TimeLaw
    scale: float
    slow: float
    peaks: tuple  # |q-dot|, |q-ddot|, |q-dddot| maxima (J,) each
    within: bool
    notes: tuple


def final_law(
    p: Plan, planned: DeviceLimits, rate: float, t_opt: float, most: int | None = None
) -> FinalLaw:
    """``most``: ``max_samples()`` when known (read once for a batch: it reads /proc files)."""
    law = p.law
    most = max_samples() if most is None else most
    notes = []
    slow = max(1.0, peak_ratio(planned.constraints(1.0 - CHECK_MARGIN), p.check.peaks))
    longest = max(1.0, MAX_SWING_DURATION / law.duration)
    cut_short = law.duration > MAX_SWING_DURATION
    if cut_short:
        # A path the limits cannot cross within the longest swing (a wandering policy's, with a
        # stop at every turn): sampled as the longest swing, faster than the limits allow, so
        # that its cost stays bounded; the peaks below say by how much (not within the limits).
        notes.append(
            f"the limits need {law.duration:.4g} s, longer than the longest swing "
            f"({MAX_SWING_DURATION:g} s): sampled at {MAX_SWING_DURATION:g} s, over a limit"
        )
        slow = MAX_SWING_DURATION / law.duration
    elif slow > longest:
        notes.append(f"slowed to the longest swing ({MAX_SWING_DURATION:g} s); still over a limit")
        slow = longest
    scale = slow
    if planned.min_duration > law.duration * scale:
        notes.append(
            f"the limits allow {t_opt:.3f} s; the minimum swing duration "
            f"{planned.min_duration:.3f} s is used"
        )
        scale = planned.min_duration / law.duration
    n = law.duration * scale * rate
    if not n < most:  # bounded before anything is allocated
        raise ValueError(
            f"rate: a {law.duration * scale:.4g} s swing at {rate:g} Hz needs {n:.4g} samples, more "
            f"than half the memory this process may use holds ({most}); lower the rate or "
            "check the device limits (joint_velocity, joint_acceleration, joint_jerk, "
            "min_swing_duration)"
        )
    scale *= max(2, math.ceil(n - 1e-9)) / n  # whole control periods: never faster
    # The check's values at the same curve points, slowed exactly (1/k, 1/k^2, 1/k^3).
    peaks = tuple(pk / scale**o for o, pk in zip((1, 2, 3), p.check.peaks))
    # A law cut short is never within the limits, whatever its sampled peaks say: the limits need
    # longer than the longest swing.
    within = not cut_short and bool(
        np.all(peaks[0] <= planned.velocity)
        and np.all(peaks[1] <= planned.acceleration)
        and (planned.jerk is None or np.all(peaks[2] <= planned.jerk))
    )
    return FinalLaw(law.slowed(scale), scale, slow, peaks, within, tuple(notes))
