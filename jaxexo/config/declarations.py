"""The declaration of a config field: ``declare(default, check, unit=..., role=...)``.

Each field is declared once, as a dataclass field whose metadata holds its ``FieldSpec``: its type
(the dataclass annotation), its check (which parses and validates the raw TOML value), its unit, and
its role in the compiled program:

- ``"leaf"``: a pytree leaf, vmappable (sweeps): an ``EnvParams`` field (env, kinematics, reward,
  layout) or a ``Hyperparams`` field (train); ``param``/``to_param`` say how it becomes one;
- ``"static"``: fixes the compiled program's shapes or structure (``static_settings``);
- ``"static+leaf"``: both (``env.max_steps``: the step limit is a leaf, but the scan length over
  episodes depends on it);
- ``"setting"``: read by the Python driver only (``train.chunk_updates``) or resolved into a
  derived static setting (``env.max_vertices`` -> ``Config.outline_vertices``).

Parsing and its messages (``config_from_dict``), the TOML writer (``jaxexo.config.toml_io``),
``HYPER_FIELDS``, ``EnvParams`` (``jaxexo.config.views.param_values``), ``Hyperparams`` and
``static_settings`` all iterate these declarations.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Any, Callable

import numpy as np

# --------------------------------------------------------------------------------------------
# The declaration of a field
# --------------------------------------------------------------------------------------------

ROLES = ("leaf", "static", "static+leaf", "setting")


@dataclass(frozen=True)
class FieldSpec:
    """How one config field is parsed, what unit it has and what it becomes (see module doc)."""

    check: Callable[[str, Any], Any]
    unit: str = ""
    role: str = "leaf"
    param: str | None = None  # EnvParams name when it differs from the field name
    # value -> {EnvParams name: NumPy value}; ``cfg`` is passed for values that need other fields.
    to_param: Callable[[Any, Any], dict] | None = None
    dtype: str = "float32"  # of the pytree leaf
    write: Callable[[Any], Any] | None = None  # value -> TOML-writable value (default: as is)
    # (EnvParams name, "section.field") for a parameter that ``to_param`` takes from another field
    params_from: tuple[tuple[str, str], ...] = ()

    @property
    def leaf(self) -> bool:
        return self.role in ("leaf", "static+leaf")

    @property
    def static(self) -> bool:
        return self.role in ("static", "static+leaf")

    def params(self, name: str, value, cfg) -> dict[str, np.ndarray]:
        if self.to_param is not None:
            return self.to_param(value, cfg)
        return {self.param or name: np.asarray(value, dtype=self.dtype)}


def declare(default=dataclasses.MISSING, check=None, *, default_factory=dataclasses.MISSING, **kw):
    """A dataclass field with its FieldSpec (in ``field.metadata["spec"]``)."""
    if check is None:
        raise TypeError("declare: every field needs a check")
    if kw.get("role", "leaf") not in ROLES:
        raise TypeError(f"declare: role must be one of {ROLES}")
    return field(
        default=default, default_factory=default_factory, metadata={"spec": FieldSpec(check, **kw)}
    )


def spec_of(f: dataclasses.Field) -> FieldSpec:
    return f.metadata["spec"]


def declared_fields(section_cls) -> list[tuple[str, FieldSpec]]:
    return [(f.name, spec_of(f)) for f in fields(section_cls)]
