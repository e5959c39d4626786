"""The check on a timed swing's curve: a time law's curve bounded piece by piece
(``with_bounds``, jaxexo.swing.limit_proof), the passes' caps lowered where a bound exceeds a limit
(``lowered_cap``), and the final law, slowed uniformly to the limits, the minimum duration and
whole control periods (``final_law``). Used by jaxexo.swing.timing; the method:
docs/device-timing.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from jaxexo.config import MAX_SWING_DURATION
from jaxexo.swing.curve import JointPath, TimeLaw
from jaxexo.swing.limit_proof import CurveBound, curve_bounds
from jaxexo.swing.limits import DeviceLimits, GridView, holds, peak_ratio

# The passes' curve must stay within (1 - this) of each limit (its proven bounds, every instant):
# headroom for the slow-down, so that the passes' local corrections leave few swings to slow.
CHECK_MARGIN = 5e-3
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
    check: CurveBound | None = None  # the law's proven bounds (``with_bounds``)


def with_bounds(plans, idx, since=None) -> list[Plan]:
    """plans[idx] with their curves' proven bounds (``limit_proof.curve_bounds``, all of them in
    one vectorised step: each curve's bounds are those it has alone; ``since``: theirs from those
    times on)."""
    plans = list(plans)
    idx = list(idx)
    for i, bound in zip(
        idx, curve_bounds([plans[i].path for i in idx], [plans[i].law for i in idx], since)
    ):
        plans[i] = replace(plans[i], check=bound)
    return plans


def lowered_cap(p: Plan, ratio) -> np.ndarray:
    """Where a piece's bound exceeds a limit (``ratio`` (N,) per piece of ``p.check``, > 1), the
    passes' cap on s'^2 lowered by the excess over the stretch of s the law's window averages
    there (the piece and one window either side)."""
    cap = p.cap.copy()
    bad = np.flatnonzero(ratio > 1.0)
    w = p.law.window
    grid = p.view.s
    c = p.check
    lo = np.searchsorted(grid, np.interp(c.t0[bad] - w, c.t, c.s), side="left") - 1
    hi = np.searchsorted(grid, np.interp(c.t1[bad] + w, c.t, c.s), side="right") + 1
    lo, hi = np.maximum(lo, 0), np.minimum(hi, len(grid))
    # At most LOCAL_SLOWEST slower per pass: a point far over a limit (a degenerate path) is left
    # to the uniform slow-down, which is bounded, rather than crawled through at no speed.
    factor = (1.0 / np.minimum(ratio[bad], LOCAL_SLOWEST)) ** 2
    # Per cell, the least factor of the pieces whose stretch [lo, hi) reaches it, linear in the
    # pieces and cells (a list of every (piece, cell) pair grew with their product: a wandering
    # swing's call once took 0.4 s).
    least = _least_over(factor, lo, hi, len(grid))
    # Where the passes already stop (s'^2 = 0: the rest ends, a cusp) a lower cap changes nothing
    # but the floor of the cells around it, which would then be crossed at no speed. x * least is
    # the least of x * factor (x >= 0: a product's rounding keeps the order).
    cells = np.flatnonzero((p.x > 0.0) & (least < np.inf))
    cap[cells] = np.minimum(cap[cells], p.x[cells] * least[cells])
    return cap


def _least_over(f: np.ndarray, lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """Per cell c of n, the least f[k] over the intervals [lo[k], hi[k]) holding c (inf: none). Each
    interval is two blocks of 2^j cells (j = floor(log2 of its length), one at each end, together
    covering it exactly), each block's minimum kept at its level; then every level's blocks are
    pushed down into their two halves, to single cells. Minima are exact, in any order."""
    keep = hi > lo
    f, lo, hi = f[keep], lo[keep], hi[keep]
    k = np.frexp((hi - lo).astype(np.float64))[1] - 1  # floor(log2(length)), exactly
    top = int(k.max()) if len(k) else 0
    levels = [np.full(n, np.inf) for _ in range(top + 1)]
    for j in range(top + 1):
        sel = np.flatnonzero(k == j)
        if len(sel):
            np.minimum.at(
                levels[j], np.concatenate([lo[sel], hi[sel] - (1 << j)]), np.tile(f[sel], 2)
            )
    for j in range(top, 0, -1):
        half = 1 << (j - 1)
        below, block = levels[j - 1], levels[j]
        np.minimum(below, block, out=below)
        np.minimum(below[half:], block[:-half], out=below[half:])
    return levels[0]


@dataclass(frozen=True)
class FinalLaw:
    """A swing's final law: the passes' law slowed by ``scale`` (the uniform slow-down ``slow``,
    the minimum duration, whole control periods), and the curve's peaks under it."""

    law: TimeLaw
    scale: float
    slow: float
    peaks: tuple  # proven bounds on max |q-dot|, |q-ddot|, |q-dddot| over the curve, (J,) each
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
    # The bounds, slowed exactly (t -> k t scales them by 1/k, 1/k^2, 1/k^3; the slowed law's
    # rounding is within limit_proof.ROUNDING): so ``within`` holds at every instant of the curve.
    peaks = tuple(pk / scale**o for o, pk in zip((1, 2, 3), p.check.peaks))
    # A law cut short is never within the limits, whatever its peaks say: the limits need longer
    # than the longest swing.
    ok = not cut_short and holds(planned.constraints(1.0), peaks)
    return FinalLaw(law.slowed(scale), scale, slow, peaks, ok, tuple(notes))
