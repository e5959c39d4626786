"""The RL generator's and CFFTG's outputs equal the stored reference (tests/reference_outputs.py):
samples, verdicts and timed swings on 2,000 scenes per generator, in the training distribution,
the three safety sets and with non-default options.

The reference was written by the code as it was before a refactor; this test is what says that
the refactor changed no output. Samples agree to 1e-6 m or rad (float32 storage; another BLAS may
round the last bits differently). A swing may differ only on a near tie, one whose clearance is
within 0.1 mm of the margin it is judged against, where such rounding can flip the verdict (and
with it the retries and the fallback); at most 0.5 % of the swings.
"""

from __future__ import annotations

import numpy as np
import pytest

from reference_outputs import FLAGS, NUMBERS, STORED, outputs

TIE = 1e-4  # m: a clearance this close to the margin is a near tie
ATOL = 1e-6


@pytest.fixture(scope="module")
def pair():
    stored = np.load(STORED)
    return {k: stored[k] for k in stored.files}, outputs()


def _near_tie(stored: dict, now: dict, key: str) -> np.ndarray:
    """Rows of ``key`` (generator/set) whose clearance is within TIE of the set's margin, as
    stored or as computed now."""
    margin = stored[f"{key}/margin"]
    return (np.abs(stored[f"{key}/min_clearance"] - margin) < TIE) | (
        np.abs(now[f"{key}/min_clearance"] - margin) < TIE
    )


def test_the_keys_are_the_stored_ones(pair):
    stored, now = pair
    assert sorted(now) == sorted(stored)


def test_samples_verdicts_and_timed_swings_equal_the_reference(pair):
    stored, now = pair
    keys = sorted({k.rsplit("/", 1)[0] for k in stored})
    total, excused, problems = 0, 0, []
    for key in keys:
        n = len(stored[f"{key}/ok"])
        assert now[f"{key}/margin"] == stored[f"{key}/margin"], key
        total += n
        differs = np.zeros(n, bool)
        first = np.full(n, "", dtype=object)  # the first field that differs, for the message
        # The reasons are text with rounded numbers: their substance is in the flags and numbers.
        for field in ("heel",) + FLAGS + NUMBERS + ("method",):
            a, b = stored[f"{key}/{field}"], now[f"{key}/{field}"]
            if a.dtype.kind == "f":
                close = np.isclose(a, b, rtol=0.0, atol=ATOL, equal_nan=True)
                row = ~close.reshape(n, -1).all(axis=1)
            else:
                row = a != b
            first[row & ~differs] = field
            differs |= row
        tie = _near_tie(stored, now, key)
        excused += int(np.sum(differs & tie))
        for i in np.flatnonzero(differs & ~tie)[:3]:
            problems.append(f"{key} row {i}: {first[i]} differs ({stored[f'{key}/reasons'][i]!r})")
        # The timed swings: one verdict and duration each, their samples concatenated.
        for field in ("timed_ok", "timed_samples"):
            if not np.array_equal(stored[f"{key}/{field}"], now[f"{key}/{field}"]):
                problems.append(f"{key}: {field} differs")
        if not problems:
            for field in ("timed_duration", "timed_joint_angles"):
                np.testing.assert_allclose(
                    now[f"{key}/{field}"],
                    stored[f"{key}/{field}"],
                    rtol=0.0,
                    atol=ATOL,
                    err_msg=f"{key}/{field}",
                )
    assert not problems, "\n".join(problems)
    assert excused <= 0.005 * total, f"{excused} of {total} swings differ on near ties"
    assert total >= 4000
