"""The declaration of a config field: ``declare(default, check, unit=..., role=...)``, its
``FieldSpec`` kept in the dataclass field's metadata. Parsing, the TOML writer, ``EnvParams``,
``Hyperparams`` and the static settings all iterate these declarations. The roles (leaf, static,
setting): docs/configuration.md#static-settings-vmappable-leaves-and-driver-settings.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Any, Callable

import numpy as np

# --------------------------------------------------------------------------------------------
# The declaration of a field
# --------------------------------------------------------------------------------------------

# leaf: a vmappable pytree leaf (EnvParams, Hyperparams); static: fixes the compiled program;
# static+leaf: both (env.max_steps); setting: read by the Python driver, or resolved into a static.
ROLES = ("leaf", "static", "static+leaf", "setting")


@dataclass(frozen=True)
class FieldSpec:
    """How one config field is parsed, what unit it has and what it becomes (roles: ``ROLES``)."""

    check: Callable[[str, Any], Any]
    unit: str = ""
    role: str = "leaf"
    param: str | None = None  # EnvParams name when it differs from the field name
    # value -> {EnvParams name: NumPy value}, or a NamedTuple of them (a section's several leaves);
    # ``cfg`` is passed for values that need other fields.
    to_param: Callable[[Any, Any], Any] | None = None
    dtype: str = "float32"  # of the pytree leaf
    write: Callable[[Any], Any] | None = None  # value -> TOML-writable value (default: as is)
    # (EnvParams name, "section.field") for a parameter that ``to_param`` takes from another field
    params_from: tuple[tuple[str, str], ...] = ()
    # A field added after configs and policies were written, whose default (off) is what they meant:
    # the writer leaves it out at its default, so that a config that does not use it writes (and a
    # run trains and exports) byte for byte what it did before the field existed, and a resolved
    # config or policy file that lacks it reads the default.
    omit_default: bool = False

    @property
    def leaf(self) -> bool:
        return self.role in ("leaf", "static+leaf")

    @property
    def static(self) -> bool:
        return self.role in ("static", "static+leaf")

    def params(self, name: str, value, cfg) -> dict[str, np.ndarray]:
        if self.to_param is not None:
            out = self.to_param(value, cfg)
            return out if isinstance(out, dict) else out._asdict()
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
