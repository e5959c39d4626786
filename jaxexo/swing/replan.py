"""Replanning in flight (NumPy only): a timed swing changed at an instant t when the obstacle turns
out other than estimated. The swing is kept as it is on [0, t]; from t a continuation over the new
obstacle to the same goal is joined to it with the joints' position, velocity and acceleration
continuous, timed within the limits from the moving state, and judged as a whole against the new
obstacle. Method and measurements: docs/replanning.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FootState:
    """Where a timed swing is at the instant ``time`` (s): the path parameter s, the swing heel (2,)
    m with its velocity (m/s) and acceleration (m/s^2), the joints (4,) rad with theirs (JOINT_NAMES
    order), and the heel's path so far (P, 2) m, from lift-off to the heel at ``time`` (the curve's
    check points on [0, s], spaced within CURVE_TOL of the curve): what a continuation starts from."""

    time: float
    path_parameter: float
    heel: np.ndarray
    heel_velocity: np.ndarray
    heel_acceleration: np.ndarray
    joints: np.ndarray
    joint_velocity: np.ndarray
    joint_acceleration: np.ndarray
    past_heel: np.ndarray
