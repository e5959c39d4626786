"""Checks of single config values: each parses one raw TOML value, ``check(path, raw) -> value``,
and raises ConfigError whose message starts with the field's ``path``, so that a bad value is named
where it was written (``layout.obstacles[1].height: must be > 0``) and never reaches a jitted run.
"""

from __future__ import annotations

import math
from typing import Any, Callable

from jaxexo.physics.kinematics import PIVOT_CONDITIONS


class ConfigError(ValueError):
    """A config value that is invalid or impossible; the message starts with the field's path."""


def _number(
    path: str, v: Any, *, positive=False, nonneg=False, integer=False, lo=None, hi=None
) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(f"{path}: expected a number, got {v!r}")
    if integer and not (isinstance(v, int) or float(v).is_integer()):
        raise ConfigError(f"{path}: expected an integer, got {v!r}")
    if not isinstance(v, int) and not math.isfinite(v):
        raise ConfigError(f"{path}: must be finite, got {v!r}")
    if positive and v <= 0:
        raise ConfigError(f"{path}: must be > 0, got {v!r}")
    if nonneg and v < 0:
        raise ConfigError(f"{path}: must be >= 0, got {v!r}")
    if lo is not None and v < lo:
        raise ConfigError(f"{path}: must be >= {lo}, got {v!r}")
    if hi is not None and v > hi:
        raise ConfigError(f"{path}: must be <= {hi}, got {v!r}")
    return int(v) if integer else float(v)


def number(*, positive=False, nonneg=False, integer=False, lo=None, hi=None) -> Callable:
    if integer and hi is None:
        raise TypeError("an integer field needs an upper bound (hi)")
    return lambda path, v: _number(
        path, v, positive=positive, nonneg=nonneg, integer=integer, lo=lo, hi=hi
    )


def fraction(positive: bool = False) -> Callable:
    """A number in [0, 1] ((0, 1] if ``positive``)."""

    def check(path, v):
        x = _number(path, v, positive=positive, nonneg=True)
        if x > 1:
            raise ConfigError(
                f"{path}: a fraction, must be in {'(0' if positive else '[0'}, 1], got {x}"
            )
        return x

    return check


def below_one(path: str, v: Any) -> float:
    x = _number(path, v, nonneg=True)
    if x >= 1:
        raise ConfigError(f"{path}: relative jitter must be < 1, got {x}")
    return x


def _vector(path: str, v: Any, n: int | None = None, **kw) -> tuple:
    if not isinstance(v, (list, tuple)):
        raise ConfigError(f"{path}: expected a list of numbers, got {v!r}")
    if n is not None and len(v) != n:
        raise ConfigError(f"{path}: expected {n} numbers, got {len(v)}")
    return tuple(_number(f"{path}[{i}]", x, **kw) for i, x in enumerate(v))


def vector(n: int | None = None, *, max_len: int | None = None, **kw) -> Callable:
    def check(path, v):
        out = _vector(path, v, n, **kw)
        if max_len is not None and len(out) > max_len:
            raise ConfigError(f"{path}: at most {max_len} numbers, got {len(out)}")
        return out

    return check


def _range(path: str, v: Any, **kw) -> tuple[float, float]:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v, v]
    lo, hi = _vector(path, v, 2, **kw)
    if lo > hi:
        raise ConfigError(f"{path}: range [lo, hi] needs lo <= hi, got [{lo}, {hi}]")
    return lo, hi


def range_(**kw) -> Callable:
    """A range [lo, hi] (a single number x means [x, x])."""
    return lambda path, v: _range(path, v, **kw)


def _choice(path: str, v: Any, options) -> str:
    if v not in options:
        raise ConfigError(f"{path}: must be one of {list(options)}, got {v!r}")
    return v


def choice(options) -> Callable:
    return lambda path, v: _choice(path, v, options)


def boolean(path: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ConfigError(f"{path}: expected true or false, got {v!r}")
    return v


def pivot_weights(path: str, v: Any) -> tuple[float, float, float]:
    """Names from PIVOT_CONDITIONS (weight 1 each), three weights in that order, or a table."""
    if isinstance(v, str):
        v = [v]
    if isinstance(v, list) and v and all(isinstance(x, str) for x in v):
        for x in v:
            _choice(path, x, PIVOT_CONDITIONS)
        return tuple(1.0 if c in v else 0.0 for c in PIVOT_CONDITIONS)
    if (
        isinstance(v, (list, tuple))
        and len(v) == len(PIVOT_CONDITIONS)
        and not any(isinstance(x, str) for x in v)
    ):
        return _vector(path, v, len(PIVOT_CONDITIONS), nonneg=True)
    if isinstance(v, dict):
        for x in v:
            _choice(f"{path}.{x}", x, PIVOT_CONDITIONS)
        return tuple(_number(f"{path}.{c}", v.get(c, 0.0), nonneg=True) for c in PIVOT_CONDITIONS)
    raise ConfigError(
        f"{path}: expected a list of names from {list(PIVOT_CONDITIONS)}, three weights "
        "in that order, or a table of weights"
    )
