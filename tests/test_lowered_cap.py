"""The passes' local correction (curve_check.lowered_cap) against a brute-force reference: every
point over a limit lowers the cap of every grid cell its window reaches, cell by cell, in plain
Python. lowered_cap does this with a range-minimum table (a wandering swing's many points over a
limit, each reaching many cells, once cost 0.4 s a call as a list of every pair)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from jaxexo.swing.curve_check import LOCAL_SLOWEST, lowered_cap


def brute_force(p, ratio, s, t):
    cap = p.cap.copy()
    grid = p.view.s
    for i in np.flatnonzero(ratio > 1.0):
        lo = max(int(np.searchsorted(grid, np.interp(t[i] - p.law.window, t, s), "left")) - 1, 0)
        hi = min(
            int(np.searchsorted(grid, np.interp(t[i] + p.law.window, t, s), "right")) + 1, len(grid)
        )
        f = (1.0 / min(ratio[i], LOCAL_SLOWEST)) ** 2
        for c in range(lo, hi):
            if p.x[c] > 0.0:
                cap[c] = min(cap[c], p.x[c] * f)
    return cap


@pytest.mark.parametrize("seed", range(40))
def test_lowered_cap_equals_the_pairwise_lowering(seed):
    rng = np.random.default_rng(seed)
    k, n = int(rng.integers(3, 60)), int(rng.integers(2, 300))
    grid = np.linspace(0.0, 1.0, k)
    t = np.sort(rng.uniform(0.0, 2.0, n))
    t[0], t[-1] = 0.0, 2.0
    s = np.sort(rng.uniform(0.0, 1.0, n))
    s[0], s[-1] = 0.0, 1.0
    if seed % 4 == 0:  # stops: s stands still over a stretch
        s[n // 3 : n // 2] = s[n // 3]
    x = rng.uniform(0.0, 2.0, k) * (rng.random(k) > 0.2)  # some cells at rest
    cap = np.where(rng.random(k) > 0.5, np.inf, rng.uniform(0.5, 3.0, k))
    ratio = rng.uniform(0.5, 1.0 + 20.0 * rng.random(), n)  # some far over (LOCAL_SLOWEST)
    p = SimpleNamespace(
        cap=cap,
        x=x,
        view=SimpleNamespace(s=grid),
        law=SimpleNamespace(window=rng.uniform(0.0, 0.5)),
    )
    np.testing.assert_array_equal(lowered_cap(p, ratio, s, t), brute_force(p, ratio, s, t))
