"""The device's limits on a timed swing (NumPy only): ``DeviceLimits`` (the config's [device]
section) and the constraint objects the passes, the check and the final law read.

The contract (docs/device-timing.md, "Limits as constraint objects"): a constraint bounds |m| <=
``limit`` (R,), m a time derivative of order ``order`` (1 speed, 2 acceleration, 3 jerk). It gives
``rows(view)``, m at the passes' grid points, a s' (order 1) or a s'' + b s'^2 + c (order 2; c an
offset), None for order 3; and ``curve_bound(d)``, a bound ``scaled + offset`` on |m| from the
proof's bounds d on |q-dot|, |q-ddot|, |q-dddot| (jaxexo.swing.limit_proof), where slowing the
swing k times divides ``scaled`` by k^order. A new limit is a new class (``DeviceLimits.extra``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from jaxexo.config import MAX_SWING_DURATION, MAX_TRACKING_HEADROOM
from jaxexo.swing.export import JOINT_NAMES
from jaxexo.swing.time_law import Rows, lane_max, lane_min


@dataclass(frozen=True)
class GridView:
    """What the passes know of a path on their grid: s (K,), q, q' and q'' (B, K, J)."""

    s: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray


@dataclass(frozen=True)
class _JointLimit:
    """|d^order q_j / dt^order| <= limit_j (J,): the proof's own bounds, one row per joint."""

    limit: np.ndarray

    def curve_bound(self, d):
        return d[self.order - 1], None

    def rows(self, view: GridView) -> None:
        return None


class JointVelocity(_JointLimit):
    """|q_j'(s) s'| <= limit_j (rad/s)."""

    order, label = 1, "joint velocity"

    def rows(self, view: GridView) -> Rows:
        return Rows(view.dq)


class JointAcceleration(_JointLimit):
    """|q_j' s'' + q_j'' s'^2| <= limit_j (rad/s^2)."""

    order, label = 2, "joint acceleration"

    def rows(self, view: GridView) -> Rows:
        return Rows(view.dq, view.ddq)


class JointJerk(_JointLimit):
    """|d3 q_j / dt3| <= limit_j (rad/s^3): the time law's window and the check see it."""

    order, label = 3, "joint jerk"


def passes_rows(constraints, view: GridView, cap: np.ndarray):
    """What the passes read from ``constraints`` on a grid's ``view``: the caps on s'^2 (B, K)
    (``cap`` lowered by every order-1 row's, (limit / |a|)^2), and every order-2 row side by side
    (time_law.Rows: a, b, c (B, K, R), bound (R,))."""
    second = []
    for c in constraints:
        r = c.rows(view)
        if r is None:
            continue
        if c.order == 1:
            ar = np.abs(r.a)
            moving = ar > 1e-12
            x = np.where(moving, (c.limit / np.where(moving, ar, 1.0)) ** 2, np.inf)
            cap = np.minimum(cap, lane_min(x))
        else:
            second.append((r.a, r.b, r.c, np.broadcast_to(c.limit, r.a.shape[-1:])))
    rows_a, rows_b, rows_c, bounds = zip(*second)
    a, b, bound = (np.concatenate(r, axis=-1) for r in (rows_a, rows_b, bounds))
    if all(x is None for x in rows_c):
        return cap, Rows(a, b, None, bound)
    off = [np.zeros_like(a) if x is None else x for a, x in zip(rows_a, rows_c)]
    return cap, Rows(a, b, np.concatenate(off, axis=-1), bound)


def _excess(c, d):
    """``c``'s scaled / (limit - offset) (R, ...) from the proof's bounds ``d`` (inf: no room)."""
    scaled, offset = c.curve_bound(d)
    limit = c.limit if scaled.ndim == 1 else c.limit[:, None]
    if offset is None:
        return scaled / limit
    room = limit - offset
    return np.where(room > 0.0, scaled / np.where(room > 0.0, room, 1.0), np.inf)


def speed_ratio(constraints, bound) -> np.ndarray:
    """Per piece of a curve (n,), the largest factor by which the swing's speed may exceed any
    constraint, from the proof's bounds on |q-dot|, |q-ddot|, |q-dddot| (3, J, n) there
    (jaxexo.swing.limit_proof): max over the rows of (scaled / (limit - offset))^(1 / order)."""
    r = np.zeros(bound.shape[-1])
    for c in constraints:
        x = lane_max(_excess(c, bound).T)
        r = np.maximum(r, x if c.order == 1 else x ** (1.0 / c.order))
    return r


def peak_ratio(constraints, peaks) -> float:
    """A bound on ``speed_ratio``'s largest value from the peaks max |q-dot|, |q-ddot|, |q-dddot|
    (J,) each (a bound is monotone in each; for the joints' own limits, that value exactly)."""
    r = 0.0
    for c in constraints:
        x = float(_excess(c, peaks).max())
        r = max(r, x ** (1.0 / c.order))
    return r


def holds(constraints, peaks) -> bool:
    """Whether every constraint's bound from the peaks (``peak_ratio``) is within its limit."""
    for c in constraints:
        scaled, offset = c.curve_bound(peaks)
        if not np.all((scaled if offset is None else scaled + offset) <= c.limit):
            return False
    return True


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
    its curve checked, against the ``planned`` limits, (1 - headroom) of these); ``extra``: further
    constraint objects (module docstring), scaled with the rest by ``planned`` and ``constraints``
    (hashable: a frozen dataclass with eq=False, say)."""

    velocity: tuple[float, float, float, float]
    acceleration: tuple[float, float, float, float]
    min_duration: float = 0.0
    jerk: tuple[float, float, float, float] | None = None
    headroom: float = 0.0
    extra: tuple = ()

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
        object.__setattr__(self, "extra", tuple(self.extra))
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
            self.extra,
        )

    def planned(self) -> "DeviceLimits":
        """What a timed reference may use: (1 - headroom) of each limit, no headroom left to take."""
        f = 1.0 - self.headroom
        return replace(self.scaled(f, f, f), headroom=0.0, extra=_times(self.extra, f))

    def constraints(self, factor: float = 1.0) -> tuple:
        """These limits (times ``factor``) as constraint objects, the ``extra`` ones last."""
        own = zip(
            (JointVelocity, JointAcceleration, JointJerk),
            (self.velocity, self.acceleration, self.jerk),
        )
        out = tuple(kind(factor * np.asarray(v)) for kind, v in own if v is not None)
        return out + _times(self.extra, factor)

    def to_dict(self) -> dict:
        return {
            "joints": list(JOINT_NAMES),
            "joint_velocity_rad_s": list(self.velocity),
            "joint_acceleration_rad_s2": list(self.acceleration),
            "joint_jerk_rad_s3": None if self.jerk is None else list(self.jerk),
            "tracking_headroom": self.headroom,
            "min_duration_s": self.min_duration,
            **({"other": [c.label for c in self.extra]} if self.extra else {}),
        }


def _times(constraints, factor: float) -> tuple:
    """Constraint objects with their limits times ``factor``."""
    return tuple(replace(c, limit=factor * np.asarray(c.limit)) for c in constraints)
