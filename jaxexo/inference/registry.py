"""Swing generators by name (jaxexo.swing.generator's interface): "rl" (TrajectoryGenerator) and
"cfftg" (CFFTG) built in, more with ``register``. The command line (--method, --against), the
evaluation, the walks and the member selection find their generators here."""

from __future__ import annotations

from jaxexo.baselines.cfftg import CFFTG
from jaxexo.inference.generator import TrajectoryGenerator
from jaxexo.swing.generator import SwingGenerator

_GENERATORS: dict[str, type[SwingGenerator]] = {}


def register(cls: type[SwingGenerator]) -> type[SwingGenerator]:
    """Register the generator class ``cls`` under its ``name`` (usable as a class decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, SwingGenerator)) or not cls.name:
        raise TypeError(f"expected a named SwingGenerator subclass, got {cls!r}")
    if _GENERATORS.get(cls.name, cls) is not cls:
        raise ValueError(f"a generator named {cls.name!r} is registered already")
    _GENERATORS[cls.name] = cls
    return cls


def names() -> tuple[str, ...]:
    """The registered generators' names, in the order they were registered."""
    return tuple(_GENERATORS)


def generator_class(name: str) -> type[SwingGenerator]:
    """The generator class registered as ``name`` (ValueError naming the registered ones)."""
    if name not in _GENERATORS:
        raise ValueError(f"no generator named {name!r} (registered: {', '.join(_GENERATORS)})")
    return _GENERATORS[name]


register(TrajectoryGenerator)
register(CFFTG)
