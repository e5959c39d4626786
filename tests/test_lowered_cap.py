"""The passes' local correction (curve_check.lowered_cap) against a brute-force reference: every
piece over a limit lowers the cap of every grid cell its stretch (its span and one window either
side) reaches, cell by cell, in plain Python. lowered_cap does this per level of power-of-two blocks
(a wandering swing's many pieces over a limit, each reaching many cells, once cost 0.4 s a call as
a list of every pair)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from jaxexo.swing.curve_check import LOCAL_SLOWEST, lowered_cap


def brute_force(p, ratio):
    cap = p.cap.copy()
    grid, c, w = p.view.s, p.check, p.law.window
    for i in np.flatnonzero(ratio > 1.0):
        lo = int(np.searchsorted(grid, np.interp(c.t0[i] - w, c.t, c.s), "left")) - 1
        hi = int(np.searchsorted(grid, np.interp(c.t1[i] + w, c.t, c.s), "right")) + 1
        f = (1.0 / min(ratio[i], LOCAL_SLOWEST)) ** 2
        for cell in range(max(lo, 0), min(hi, len(grid))):
            if p.x[cell] > 0.0:
                cap[cell] = min(cap[cell], p.x[cell] * f)
    return cap


@pytest.mark.parametrize("seed", range(40))
def test_lowered_cap_equals_the_pairwise_lowering(seed):
    rng = np.random.default_rng(seed)
    k, n, m = int(rng.integers(3, 80)), int(rng.integers(2, 300)), int(rng.integers(2, 60))
    grid = np.linspace(0.0, 1.0, k)
    t = np.sort(rng.uniform(0.0, 2.0, m))  # the law's breakpoints and s there (non-decreasing)
    t[0], t[-1] = 0.0, 2.0
    s = np.sort(rng.uniform(0.0, 1.0, m))
    s[0], s[-1] = 0.0, 1.0
    if seed % 4 == 0:  # a stop: s stands still over a stretch
        s[m // 3 : m // 2] = s[m // 3]
    t0 = rng.uniform(0.0, 2.0, n)  # pieces in any order, overlapping, some of zero length
    t1 = np.minimum(t0 + rng.exponential(0.2, n) * (rng.random(n) > 0.1), 2.0)
    x = rng.uniform(0.0, 2.0, k) * (rng.random(k) > 0.2)  # some cells at rest
    cap = np.where(rng.random(k) > 0.5, np.inf, rng.uniform(0.5, 3.0, k))
    ratio = rng.uniform(0.5, 1.0 + 20.0 * rng.random(), n)  # some far over (LOCAL_SLOWEST)
    p = SimpleNamespace(
        cap=cap,
        x=x,
        view=SimpleNamespace(s=grid),
        law=SimpleNamespace(window=rng.uniform(0.0, 0.5)),
        check=SimpleNamespace(t=t, s=s, t0=t0, t1=t1),
    )
    np.testing.assert_array_equal(lowered_cap(p, ratio), brute_force(p, ratio))
