"""The one summary record and Markdown table builder (jaxexo.summary)."""

from __future__ import annotations

import math
import statistics

import numpy as np

from jaxexo.summary import Summary, table


def test_summary_is_numpys_own_figures():
    rng = np.random.default_rng(0)
    for x in (rng.random(7), rng.random(8).astype(np.float32), [0.3, 0.1, 0.2, 0.4]):
        s = Summary.of(x)
        a = np.asarray(x)
        assert s.n == a.size and s.mean == float(a.mean()) and s.median == float(np.median(a))
        assert s.p5 == float(np.percentile(a, 5)) and s.p95 == float(np.percentile(a, 95))
        assert (s.min, s.max) == (float(a.min()), float(a.max()))
    times = list(rng.random(6))
    assert Summary.of(times).median == statistics.median(times)


def test_empty_sample_and_ratio():
    e = Summary.of([])
    assert e.n == 0 and math.isnan(e.median) and math.isnan(e.p95)
    a, b = Summary.of([2.0, 4.0, 6.0]), Summary.of([1.0, 2.0, 3.0])
    r = a.over(b)
    assert r.n == 3 and r.median == 2.0 and r.max == 2.0 and r.p95 == a.p95 / b.p95
    assert r.to_dict()["median"] == 2.0


def test_table():
    assert table(("a", "b", "c"), [(1, "x", 2.5)], "lrl") == [
        "| a | b | c |",
        "|---|---:|---|",
        "| 1 | x | 2.5 |",
    ]
    assert table(("a", "b"), [])[1] == "|---|---:|"
    assert table(("a", "b", "c"), [("x", "", "")])[2] == "| x | | |"
