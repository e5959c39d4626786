"""The device's limits on a timed swing (NumPy only): ``DeviceLimits`` (the config's [device]
section) and the constraint objects the time law's passes and checks read.

A constraint gives the TOPP passes what it asks of the path's speed s' (a cap on s'^2, or rows
|a(s) s'' + b(s) s'^2| <= bound) and gives the check its ratio on the curve in speed units (the
factor by which the swing must be slowed to meet it: a velocity scales with 1/k, an acceleration
with 1/k^2, a jerk with 1/k^3). A new limit (a torque, a heel speed) is a new constraint class; the
passes and the check do not change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from jaxexo.config import MAX_SWING_DURATION, MAX_TRACKING_HEADROOM
from jaxexo.swing.export import JOINT_NAMES
from jaxexo.swing.time_law import lane_max, lane_min


@dataclass(frozen=True)
class GridView:
    """What the passes know of a path on their grid: s (K,), q' and q'' (B, K, J)."""

    s: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray


@dataclass(frozen=True)
class PathBounds:
    """A constraint's demands on the passes: caps on s'^2 (B, K) or None, and acceleration rows
    |a s'' + b s'^2| <= bound, a and b (B, K, R), bound (R,) (None: no rows)."""

    x_cap: np.ndarray | None = None
    a: np.ndarray | None = None
    b: np.ndarray | None = None
    bound: np.ndarray | None = None


@dataclass(frozen=True)
class JointVelocity:
    """|q_j'(s) s'| <= limit_j (rad/s)."""

    limit: np.ndarray
    power = 1.0
    label = "joint velocity"

    def path_bounds(self, view: GridView) -> PathBounds:
        adq = np.abs(view.dq)
        with np.errstate(divide="ignore"):
            cap = np.where(adq > 1e-12, (self.limit / np.maximum(adq, 1e-300)) ** 2, np.inf)
        return PathBounds(x_cap=lane_min(cap))


@dataclass(frozen=True)
class JointAcceleration:
    """|q_j'' s'^2 + q_j' s''| <= limit_j (rad/s^2)."""

    limit: np.ndarray
    power = 2.0
    label = "joint acceleration"

    def path_bounds(self, view: GridView) -> PathBounds:
        return PathBounds(a=view.dq, b=view.ddq, bound=self.limit)


@dataclass(frozen=True)
class JointJerk:
    """|d3 q_j / dt3| <= limit_j (rad/s^3): the passes do not see it; the time law's window and the
    check do."""

    limit: np.ndarray
    power = 3.0
    label = "joint jerk"

    def path_bounds(self, view: GridView) -> PathBounds:
        return PathBounds()


def passes_rows(constraints, view: GridView, cap: np.ndarray):
    """What the passes read from ``constraints`` on a grid's ``view``: the caps on s'^2 (B, K)
    (``cap`` lowered by each constraint's own), and the acceleration rows a, b (B, K, R) with their
    bounds (R,), every constraint's rows side by side."""
    rows_a, rows_b, bounds = [], [], []
    for c in constraints:
        pb = c.path_bounds(view)
        if pb.x_cap is not None:
            cap = np.minimum(cap, pb.x_cap)
        if pb.a is not None:
            rows_a.append(pb.a)
            rows_b.append(pb.b)
            bounds.append(np.broadcast_to(pb.bound, pb.a.shape[-1:]))
    a, b, bound = (np.concatenate(r, axis=-1) for r in (rows_a, rows_b, bounds))
    return cap, a, b, bound


def speed_ratio(constraints, bound) -> np.ndarray:
    """Per piece of a curve (n,), the largest factor by which the swing's speed may exceed any
    constraint, from the bounds on |q-dot|, |q-ddot|, |q-dddot| (3, J, n) there
    (jaxexo.swing.limit_proof): max over the joints of (bound / limit)^(1 / power)."""
    r = np.zeros(bound.shape[-1])
    for c in constraints:
        x = lane_max((bound[int(c.power) - 1] / c.limit[:, None]).T)
        r = np.maximum(r, x if c.power == 1.0 else x ** (1.0 / c.power))
    return r


def peak_ratio(constraints, peaks) -> float:
    """``speed_ratio``'s largest value from the peaks max |q-dot|, max |q-ddot|, max |q-dddot| (J,)
    each (the ratio is monotone in each value, so the peak of the ratio is the ratio of the
    peaks)."""
    r = 0.0
    for c in constraints:
        x = float((peaks[int(c.power) - 1] / c.limit).max())
        r = max(r, x ** (1.0 / c.power))
    return r


def _positive_vector(name: str, v) -> tuple[float, ...]:
    n = len(JOINT_NAMES)
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"limits.{name}: expected {n} numbers, got {v!r}") from None
    if arr.shape != (n,):
        raise ValueError(
            f"limits.{name}: expected {n} numbers ({', '.join(JOINT_NAMES)}), got {v!r}"
        )
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
        raise ValueError(f"limits.{name}: every limit must be finite and > 0, got {v!r}")
    return tuple(float(x) for x in arr)


@dataclass(frozen=True)
class DeviceLimits:
    """Peak joint velocity (rad/s), acceleration (rad/s^2) and jerk (rad/s^3; None: unbounded) per
    joint of JOINT_NAMES, the shortest swing allowed (s), and the tracking headroom: the fraction of
    each limit the timed reference leaves free for the feedback controller (a swing is timed, and
    its curve checked, against the ``planned`` limits, (1 - headroom) of these)."""

    velocity: tuple[float, float, float, float]
    acceleration: tuple[float, float, float, float]
    min_duration: float = 0.0
    jerk: tuple[float, float, float, float] | None = None
    headroom: float = 0.0

    def __post_init__(self):
        h = self.headroom
        if (
            isinstance(h, bool)
            or not isinstance(h, (int, float))
            or not (0.0 <= h <= MAX_TRACKING_HEADROOM)
        ):
            raise ValueError(
                f"limits.headroom: must be a number in [0, {MAX_TRACKING_HEADROOM:g}] (a fraction "
                f"of each limit), got {h!r}"
            )
        object.__setattr__(self, "headroom", float(h))
        for name in ("velocity", "acceleration", "jerk"):
            v = getattr(self, name)
            if not (v is None and name == "jerk"):
                object.__setattr__(self, name, _positive_vector(name, v))
        d = self.min_duration
        # The [device] section's bound (min_swing_duration): a swing, not a walk.
        if (
            isinstance(d, (bool, np.bool_))
            or not isinstance(d, (int, float, np.integer, np.floating))
            or not (math.isfinite(d) and 0.0 <= d <= MAX_SWING_DURATION)
        ):
            raise ValueError(
                f"limits.min_duration: must be a number of seconds in [0, {MAX_SWING_DURATION:g}] "
                f"(a swing), got {d!r}"
            )
        object.__setattr__(self, "min_duration", float(d))

    @classmethod
    def from_config(cls, config) -> "DeviceLimits":
        """The [device] section's (hip, knee) limits, applied to both legs."""
        dev = config.device
        (vh, vk), (ah, ak), (jh, jk) = dev.joint_velocity, dev.joint_acceleration, dev.joint_jerk
        return cls(
            (vh, vk, vh, vk),
            (ah, ak, ah, ak),
            dev.min_swing_duration,
            (jh, jk, jh, jk),
            dev.tracking_headroom,
        )

    def scaled(
        self, velocity: float = 1.0, acceleration: float = 1.0, jerk: float | None = None
    ) -> "DeviceLimits":
        """The limits times these factors (jerk: by the acceleration's factor unless given)."""
        jerk = acceleration if jerk is None else jerk
        return DeviceLimits(
            tuple(velocity * v for v in self.velocity),
            tuple(acceleration * a for a in self.acceleration),
            self.min_duration,
            None if self.jerk is None else tuple(jerk * j for j in self.jerk),
            self.headroom,
        )

    def planned(self) -> "DeviceLimits":
        """What a timed reference may use: (1 - headroom) of each limit, no headroom left to take."""
        f = 1.0 - self.headroom
        return DeviceLimits(
            tuple(f * v for v in self.velocity),
            tuple(f * a for a in self.acceleration),
            self.min_duration,
            None if self.jerk is None else tuple(f * j for j in self.jerk),
            0.0,
        )

    def constraints(self, factor: float = 1.0) -> tuple:
        """These limits (times ``factor``) as constraint objects."""
        out = [
            JointVelocity(factor * np.asarray(self.velocity)),
            JointAcceleration(factor * np.asarray(self.acceleration)),
        ]
        if self.jerk is not None:
            out.append(JointJerk(factor * np.asarray(self.jerk)))
        return tuple(out)

    def to_dict(self) -> dict:
        return {
            "joints": list(JOINT_NAMES),
            "joint_velocity_rad_s": list(self.velocity),
            "joint_acceleration_rad_s2": list(self.acceleration),
            "joint_jerk_rad_s3": None if self.jerk is None else list(self.jerk),
            "tracking_headroom": self.headroom,
            "min_duration_s": self.min_duration,
        }
