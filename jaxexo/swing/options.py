"""The options shared by every generator (the RL policy, CFFTG): one frozen record and its checks.

``generate(obstacle, options, **overrides)`` takes a ``SwingOptions`` (CFFTG) or ``GenerateOptions``
(the RL generator: also its smoothing and fallback), checked once when made: an error names the
field. A swing is asked for by an obstacle and where the feet are: the pivot (stance) heel, the
swing heel's start and the step length; their defaults are jaxexo.physics.scene's (DEFAULT_PIVOT,
DEFAULT_START_Y, DEFAULT_STEP_LENGTH), and they are checked with the obstacle when its scene is laid
out (the generators' ``scene``, jaxexo.swing.generator: jaxexo.physics.scene.make_scene).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from jaxexo.config import MAX_SWING_DURATION
from jaxexo.physics import geometry
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics.scene import (
    DEFAULT_START_Y,
    DEFAULT_STEP_LENGTH,
    MAX_CLEARANCE,
)
from jaxexo.swing.smoothing import DEFAULT_POINTS
from jaxexo.swing.trajectory import DEFAULT_DURATION, TrajectoryBatch, TrajectoryError

# Bounds of the sizes taken from input, checked before anything is allocated.
MAX_POINTS = 100_000  # samples of one path
MAX_DURATION = MAX_SWING_DURATION  # s: a swing, not a walk (jaxexo.config)
# Fewer samples cannot follow a swing over an obstacle: with 2-10 the checks judged the path between
# them with clearances and backward moves of metres.
MIN_POINTS = 20
# s: no joint drive swings a leg in less (below about 1e-4 s the CSV's time column read all zeros).
MIN_DURATION = 0.01

FALLBACKS = ("cfftg", None)


def check_points(n_points, name: str = "n_points") -> int:
    """Samples of a path: an integer in [MIN_POINTS, MAX_POINTS]; ValueError naming ``name``."""
    if (
        isinstance(n_points, bool)
        or not isinstance(n_points, (int, np.integer))
        or not (MIN_POINTS <= n_points <= MAX_POINTS)
    ):
        raise ValueError(
            f"{name} must be an integer in [{MIN_POINTS}, {MAX_POINTS}], got {n_points!r}"
        )
    return int(n_points)


def check_duration(duration, name: str = "duration") -> float:
    """A swing's duration in [MIN_DURATION, MAX_DURATION] s; ValueError naming ``name``."""
    duration = geometry.finite_positive(name, duration, "s")
    if duration > MAX_DURATION:
        raise ValueError(
            f"{name} must be <= {MAX_DURATION:g} s (one swing), got {geometry.as_given(duration)}"
        )
    if duration < MIN_DURATION:
        raise ValueError(
            f"{name} must be >= {MIN_DURATION:g} s (no drive swings a leg faster), got "
            f"{geometry.as_given(duration)}"
        )
    return duration


def check_flag(value, name: str) -> bool:
    """A yes/no option: True or False only (``strict="no"`` would be taken as true)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}: expected True or False, got {value!r}")
    return bool(value)


def check_smoothing(smoothing):
    """The spline's smoothing s (m^2, >= 0), or None (the model's); ValueError naming the option."""
    if smoothing is None:
        return None
    smoothing = geometry.finite("smoothing", smoothing, "m^2")
    if smoothing < 0:
        raise ValueError(f"smoothing must be >= 0 (m^2), got {geometry.as_given(smoothing)}")
    return smoothing


def check_fallback(fallback):
    """ "cfftg" or None ("none" from a command line)."""
    if fallback == "none":
        return None
    if fallback not in FALLBACKS:
        raise ValueError(f"fallback must be 'cfftg' or None, got {fallback!r}")
    return fallback


def _check_strict(strict) -> bool:
    return check_flag(strict, "strict")


def _check_pivot(name: str, v) -> None:
    if isinstance(v, str):
        if v not in PIVOT_CONDITIONS:
            raise ValueError(
                f"{name} must be one of {PIVOT_CONDITIONS} or a y in metres, got {v!r}"
            )
    elif v is not None:
        geometry.finite(name, v)


def _check_pivot_y(name: str, v) -> None:
    if v is not None:
        geometry.finite(name, v)


SCENE_CHECKS = (
    ("pivot", _check_pivot),
    ("pivot_y", _check_pivot_y),
    ("start_y", geometry.finite),
    ("step_length", geometry.finite_positive),
)


def check_scene_fields(options) -> None:
    """The scene's fields, each one value or one per obstacle (a list, tuple or array), checked when
    the record is made: a pivot condition's name or a y, finite metres, a positive step length. The
    obstacle's own checks (where it lies from the start and the goal) wait for it (make_scene)."""
    for name, check in SCENE_CHECKS:
        v = getattr(options, name)
        if isinstance(v, (list, tuple, np.ndarray)):
            for i, x in enumerate(np.asarray(v, dtype=object).ravel()):
                check(f"{name}[{i}]", x)
        else:
            check(name, v)


def _column(v) -> list | None:
    """A per-obstacle column's values, or None for one value for all."""
    if isinstance(v, (list, tuple, np.ndarray)):
        return list(np.asarray(v, dtype=object).ravel())
    return None


def check_pivot_pair(pivot, pivot_y) -> None:
    """``pivot`` (a condition) and ``pivot_y`` (m) are two ways to place the pivot heel: refused
    where both are given, for one obstacle or at the same obstacle of two columns (ValueError naming
    both, with their index in a column)."""
    cp, cy = _column(pivot), _column(pivot_y)
    n = max(len(c) for c in (cp, cy, [None]) if c is not None)
    for i in range(n):
        p = pivot if cp is None else (cp[i] if i < len(cp) else None)
        y = pivot_y if cy is None else (cy[i] if i < len(cy) else None)
        if p is not None and y is not None:
            at = "" if cp is None and cy is None else f"[{i}]"
            raise ValueError(
                f"pivot{at if cp is not None else ''}, pivot_y{at if cy is not None else ''}: give "
                f"one of them (a condition or a y in metres), got pivot={p!r} and pivot_y={y!r}"
            )


def check_clearance_field(clearance):
    """None (the model's env.min_clearance) or a finite number of metres in [0, MAX_CLEARANCE]; the
    model's own lower bound is checked against its config when the swing is made (at_clearance)."""
    if clearance is None:
        return None
    if isinstance(clearance, (bool, np.bool_)) or not isinstance(
        clearance, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"clearance: expected a number of metres, got {type(clearance).__name__}")
    c = float(clearance)
    if not (math.isfinite(c) and 0.0 <= c <= MAX_CLEARANCE):
        raise ValueError(
            f"clearance must be a finite number of metres in [0, {MAX_CLEARANCE:g}], got {clearance!r}"
        )
    return clearance


@dataclass(frozen=True)
class SwingOptions:
    """What every generator's ``generate`` / ``generate_batch`` takes besides the obstacles (metres,
    seconds), checked when made (``CHECKS``, in order; an error names the field). The scene's fields
    (``SCENE_FIELDS``) are one value, or in generate_batch one per obstacle; ``pivot_y``, when given,
    replaces the ``pivot`` condition; they are checked with the obstacle (the generators' ``scene``).
    ``strict`` raises TrajectoryError instead of returning a swing that fails a check (``checked``);
    ``clearance`` (m; None: the model's env.min_clearance) is the margin the swing keeps
    (the generators' ``at_clearance``, which checks it against the model)."""

    pivot: Any = None
    pivot_y: Any = None
    start_y: Any = DEFAULT_START_Y
    step_length: Any = DEFAULT_STEP_LENGTH
    n_points: int = DEFAULT_POINTS
    duration: float = DEFAULT_DURATION
    strict: bool = False
    clearance: float | None = None

    SCENE_FIELDS: ClassVar[tuple[str, ...]] = ("pivot", "pivot_y", "start_y", "step_length")
    CHECKS: ClassVar[tuple] = (
        ("n_points", check_points),
        ("duration", check_duration),
        ("strict", _check_strict),
        ("clearance", check_clearance_field),
    )

    def __post_init__(self):
        for name, check in self.CHECKS:
            object.__setattr__(self, name, check(getattr(self, name)))
        check_scene_fields(self)
        check_pivot_pair(self.pivot, self.pivot_y)

    @property
    def scene_args(self) -> tuple:
        """(pivot, pivot_y, start_y, step_length): the generators' ``scene`` arguments."""
        return tuple(getattr(self, name) for name in self.SCENE_FIELDS)

    @classmethod
    def given(cls, options, overrides: dict, where: str):
        """``options`` (None: the defaults; a SwingOptions of another kind keeps the fields both have)
        with ``overrides`` (``generate``'s keywords) replacing its fields, checked once. TypeError
        naming a keyword that is not a field, or ``options`` that are not options."""
        names = [f.name for f in dataclasses.fields(cls)]
        unknown = [k for k in overrides if k not in names]
        if unknown:
            raise TypeError(f"{unknown[0]}: not an option of {where} (options: {', '.join(names)})")
        if options is None:
            return cls(**overrides)
        if not isinstance(options, SwingOptions):
            raise TypeError(f"options: expected {cls.__name__}, got {type(options).__name__}")
        if not isinstance(options, cls):
            shared = {
                f.name: getattr(options, f.name)
                for f in dataclasses.fields(options)
                if f.name in names
            }
            return cls(**{**shared, **overrides})
        return dataclasses.replace(options, **overrides) if overrides else options

    def checked(self, result):
        """A trajectory or batch as generated, or with ``strict`` TrajectoryError on its first failed swing."""
        if self.strict and not np.all(result.ok):
            batch = isinstance(result, TrajectoryBatch)
            raise TrajectoryError(result[int(np.argmin(result.ok))] if batch else result)
        return result


@dataclass(frozen=True)
class GenerateOptions(SwingOptions):
    """The RL generator's options: every generator's (``SwingOptions``) and ``smoothing``, the
    spline's s (m^2; None: the model's, TrajectoryGenerator.smoothing) and ``fallback``: "cfftg"
    (CFFTG's plan replaces a swing that is not safe) or None. CFFTG takes these too and uses the
    fields it has."""

    smoothing: float | None = None
    fallback: str | None = "cfftg"

    # the order generate checked its keywords in: with several bad values, the same one is named
    CHECKS: ClassVar[tuple] = (
        ("n_points", check_points),
        ("smoothing", check_smoothing),
        ("duration", check_duration),
        ("fallback", check_fallback),
        ("strict", _check_strict),
        ("clearance", check_clearance_field),
    )
