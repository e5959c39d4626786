"""[env] obstacle_change: training episodes whose obstacle changes at a random step (taller, wider,
moved, or a second one appearing), so that a policy learns to continue from a mid-swing state over an
obstacle other than the one it started with. ``parse_change`` reads the field (off, a chance, or a
table), ``change_params`` gives its EnvParams leaves; the change itself is
jaxexo.physics.changes'. What it does: docs/training.md#obstacle-changes-in-training.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, NamedTuple

import numpy as np

from jaxexo.config.checks import ConfigError, _number, _range

# Upper bounds of the ranges: an obstacle at most three times as tall or as wide as drawn, moved at
# most 20 cm (beyond that it is another scene, not a correction of the estimate).
MAX_GROWTH = 2.0
MAX_MOVE = 0.20
MAX_CHANGE_STEP = 100_000


@dataclass(frozen=True)
class ChangeSpec:
    """The obstacle change of a training episode: with probability ``chance``, at a step drawn
    uniformly from ``steps`` (inclusive), the obstacle becomes a second-obstacle scene (probability
    ``second``) or its height grows by a fraction drawn from ``taller``, its width by one from
    ``wider`` and it moves by ``move`` metres along y (all three at once)."""

    chance: float = 0.5
    steps: tuple[int, int] = (5, 14)
    taller: tuple[float, float] = (0.0, 0.6)
    wider: tuple[float, float] = (0.0, 0.5)
    move: tuple[float, float] = (0.0, 0.05)
    second: float = 0.25


CHANGE_KEYS = tuple(f.name for f in fields(ChangeSpec))


def _fraction(path: str, v: Any) -> float:
    x = _number(path, v, nonneg=True)
    if x > 1:
        raise ConfigError(f"{path}: a probability, must be in [0, 1], got {v!r}")
    return x


def _steps(path: str, v: Any) -> tuple[int, int]:
    lo, hi = _range(path, v, integer=True, lo=1, hi=MAX_CHANGE_STEP)
    return int(lo), int(hi)


_KEY_CHECKS = {
    "chance": _fraction,
    "steps": _steps,
    "taller": lambda path, v: _range(path, v, nonneg=True, hi=MAX_GROWTH),
    "wider": lambda path, v: _range(path, v, nonneg=True, hi=MAX_GROWTH),
    "move": lambda path, v: _range(path, v, lo=-MAX_MOVE, hi=MAX_MOVE),
    "second": _fraction,
}


def parse_change(path: str, v: Any) -> ChangeSpec | None:
    """[env] obstacle_change: ``0`` or ``false`` (off, the default), a probability in (0, 1] (on, the
    other settings at ChangeSpec's defaults), or a table of ChangeSpec's fields (chance, steps,
    taller, wider, move, second; the ones left out take the defaults). A chance of 0 is off.
    ConfigError naming ``path`` (and the key) otherwise."""
    if v is None or v is False or isinstance(v, ChangeSpec):
        return v or None
    if v is True:
        v = {}
    if isinstance(v, (int, float)):
        chance = _fraction(path, v)
        return ChangeSpec(chance=chance) if chance > 0 else None
    if not isinstance(v, dict):
        raise ConfigError(
            f"{path}: expected 0 (off), a probability in (0, 1] or a table of "
            f"{', '.join(CHANGE_KEYS)}, got {v!r}"
        )
    unknown = sorted(set(v) - set(CHANGE_KEYS))
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(CHANGE_KEYS)})")
    spec = ChangeSpec(**{k: _KEY_CHECKS[k](f"{path}.{k}", x) for k, x in v.items()})
    return spec if spec.chance > 0 else None


def write_change(spec: ChangeSpec | None) -> Any:
    """The TOML value of a ChangeSpec (off: 0.0; the writer leaves the field out then)."""
    if spec is None:
        return 0.0
    return {k: list(x) if isinstance(x, tuple) else x for k, x in vars(spec).items()}


class ChangeLeaves(NamedTuple):
    """The obstacle change's EnvParams leaves."""

    change_chance: np.ndarray  # () the chance an episode's obstacle changes
    change_steps: np.ndarray  # [2] int32, the step range of the switch
    change_taller: np.ndarray  # [2] the height's growth range (fraction)
    change_wider: np.ndarray  # [2] the width's growth range (fraction)
    change_move: np.ndarray  # [2] m, the move range
    change_second: np.ndarray  # () the chance of a second obstacle
    change_max_height: np.ndarray  # () m, the tallest obstacle the layout draws


def change_params(spec: ChangeSpec | None, cfg) -> ChangeLeaves:
    """The change as EnvParams leaves (off: ChangeSpec's defaults at chance 0, never read: the switch
    is static, jaxexo.env's ``obstacle_change``) and the tallest obstacle the layout draws, which a
    taller obstacle or a second one never exceeds (the config's checks make that one clearable)."""
    s = ChangeSpec(chance=0.0) if spec is None else spec
    lay = cfg.layout
    tallest = (
        lay.terrain.max_height
        if lay.terrain is not None
        else max(o.height[1] * (1.0 + lay.size_jitter) for o in lay.obstacles)
    )
    f = lambda x: np.asarray(x, dtype=np.float32)  # noqa: E731
    return ChangeLeaves(
        change_chance=f(s.chance),
        change_steps=np.asarray(s.steps, dtype=np.int32),
        change_taller=f(s.taller),
        change_wider=f(s.wider),
        change_move=f(s.move),
        change_second=f(s.second),
        change_max_height=f(tallest),
    )


__all__ = ["ChangeSpec", "CHANGE_KEYS", "parse_change", "write_change", "change_params"]
