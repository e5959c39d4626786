"""Measures of a heel path that the comparison and the held-out benchmark report alike.

NumPy only; kept apart from ``compare`` so that the benchmarks that use them do not import each other.
"""

from __future__ import annotations

import numpy as np


def path_length(heel: np.ndarray) -> np.ndarray:
    """Length of heel paths (..., N, 2), metres."""
    return np.linalg.norm(np.diff(heel, axis=-2), axis=-1).sum(axis=-1)
