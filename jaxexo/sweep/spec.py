"""Sweep files (NumPy only): a config with a [sweep] table of seeds and grid and random axes over any
config field (``section.field`` or ``section.field[i]``), read, validated (a bad value refused at load
time naming the axis and the field), expanded into configurations and grouped by static settings
(jaxexo.config.static_settings: each group is one compiled program). An *agent* is one
(configuration, seed) pair. The file's format: docs/training.md (Hyperparameter sweeps).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from jaxexo.config import (
    Config,
    ConfigError,
    check_seed,
    config_from_dict,
    declared_fields,
    static_settings,
    validate,
)
from jaxexo.config.input_files import InputFileError, read_text_input

SECTIONS = ("env", "kinematics", "reward", "layout", "train")
# The [sweep] fields that decide the results (Sweep.fingerprint), and all of them.
RESULT_KEYS = ("seeds", "samples", "sample_seed", "grid", "random")
SWEEP_KEYS = ("base", *RESULT_KEYS, "heatmap", "top", "chunk_size", "memory_budget")
RANDOM_KEYS = ("low", "high", "log", "choices")
# Configurations of one sweep (grid points x samples), counted from the axes before any is built.
MAX_CONFIGURATIONS = 10_000
_AXIS = re.compile(r"([a-z_]+)\.([a-z_0-9]+)(?:\[(\d+)\])?")


@dataclass(frozen=True)
class Axis:
    path: str  # "train.lr", "reward.traj_weights[3]"
    section: str
    field: str
    index: int | None
    kind: str  # "grid" or "random"
    values: tuple = ()  # grid: the values; random: the choices (if any)
    low: float | None = None  # random range
    high: float | None = None
    log: bool = False
    integer: bool = False  # random range over an integer field: integers in [low, high]

    @property
    def where(self) -> str:
        return f"sweep.{self.kind}.{self.path}"


@dataclass(frozen=True)
class Member:
    """One configuration of the sweep: its axis values and the full validated config."""

    config_id: int
    values: dict
    config: Config

    @property
    def label(self) -> str:
        return ", ".join(f"{k}={format_value(v)}" for k, v in self.values.items())


@dataclass(frozen=True)
class Group:
    """Configurations with equal static settings: one compiled program. ``agents`` lists
    (config_id, seed) in order: configuration by configuration, every seed of each."""

    group_id: int
    config_ids: tuple[int, ...]
    agents: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class Sweep:
    raw: dict  # the merged base config table (without [sweep])
    table: dict  # the [sweep] table as written (base resolved)
    axes: tuple[Axis, ...]
    seeds: tuple[int, ...]
    members: tuple[Member, ...]
    groups: tuple[Group, ...]
    heatmap: tuple[str, ...]
    top: int
    chunk_size: int | None
    memory_budget: int | None  # bytes

    @property
    def num_agents(self) -> int:
        return len(self.members) * len(self.seeds)

    def fingerprint(self) -> str:
        """Hash of everything that decides the results (not the report options or the chunking)."""
        keep = {k: v for k, v in self.table.items() if k in RESULT_KEYS}
        text = json.dumps({"raw": self.raw, "sweep": keep}, sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def to_dict(self) -> dict:
        """The self-contained sweep (base merged in), which ``sweep_from_dict`` rebuilds exactly: what
        a Ray worker receives."""
        return {
            **copy.deepcopy(self.raw),
            "sweep": {k: v for k, v in self.table.items() if k != "base"},
        }


def format_value(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return "[" + ",".join(format_value(x) for x in v) + "]"
    return str(v)


# --------------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------------


def _read_toml(path: Path, what: str) -> dict:
    try:
        text = read_text_input(path, "sweep file" if what == "sweep file" else "config")
    except InputFileError as e:
        raise ConfigError(f"{what}: {e}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{what}: {path} is not valid TOML ({e})") from None


def deep_merge(base: dict, over: dict) -> dict:
    """``over`` on top of ``base``: tables merge key by key, any other value replaces."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        out[k] = (
            deep_merge(out[k], v)
            if isinstance(v, dict) and isinstance(out.get(k), dict)
            else copy.deepcopy(v)
        )
    return out


def _base_config(path: Path, base: str) -> dict:
    """The table of the config ``sweep.base`` names (relative to the sweep file ``path``): a model's
    config, never this sweep file itself nor another sweep file (whose [sweep] table would be dropped
    and whose own base not followed, training some other model without a word)."""
    target = (path.parent / base).resolve()
    try:
        same = target.exists() and target.samefile(path)
    except OSError:
        same = False
    if same:
        raise ConfigError(
            f"sweep.base: {base!r} is this sweep file itself; name the config file the sweep varies"
        )
    base_raw = _read_toml(target, "sweep.base")
    if "sweep" in base_raw:
        raise ConfigError(
            f"sweep.base: {target} is a sweep file (it has a [sweep] table); a sweep's base is one "
            "model's config file"
        )
    return base_raw


def load_sweep(path: str | Path) -> Sweep:
    """Read, validate and expand a sweep file; errors name the file and the field."""
    path = Path(path)
    raw = _read_toml(path, "sweep file")
    try:
        table = raw.pop("sweep", None)
        if table is None:
            raise ConfigError("sweep: missing [sweep] table (axes and seeds)")
        if not isinstance(table, dict):
            raise ConfigError(f"sweep: expected a table, got {table!r}")
        table = dict(table)
        if "base" in table:
            base = table["base"]
            if not isinstance(base, str):
                raise ConfigError(f"sweep.base: expected a path to a config file, got {base!r}")
            raw = deep_merge(_base_config(path, base), raw)
        return sweep_from_dict({**raw, "sweep": table})
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def sweep_from_dict(raw: dict) -> Sweep:
    """Build a Sweep from a parsed sweep table (config sections plus [sweep]; ``sweep.base`` is
    ignored here: load_sweep resolves it)."""
    raw = copy.deepcopy(raw)
    table = raw.pop("sweep", None)
    if not isinstance(table, dict):
        raise ConfigError("sweep: missing [sweep] table (axes and seeds)")
    unknown = sorted(set(table) - set(SWEEP_KEYS))
    if unknown:
        raise ConfigError(f"sweep.{unknown[0]}: unknown field (known: {', '.join(SWEEP_KEYS)})")
    # The sweep's seeds are its population: a config that leaves train.population to the default
    # model's (2) trains each agent once here; only a stated population > 1 is refused below.
    if isinstance(raw.get("train", {}), dict):
        raw.setdefault("train", {}).setdefault("population", 1)
    base = config_from_dict(raw)
    axes = _axes(table, base)
    seeds = _seeds(table.get("seeds", 1))
    samples = _samples(table, axes)
    _check_size(axes, samples)
    sample_seed = _int("sweep.sample_seed", table.get("sample_seed", 0), minimum=0)
    members = _expand(raw, base, axes, samples, sample_seed)
    if any(m.config.train.population != 1 for m in members):
        # A sweep's agents are its configurations x [sweep] seeds; each trains once, its final parameters
        # kept. A population inside a sweep cell would be a second, silent seed axis.
        raise ConfigError(
            "train.population: a sweep trains its seeds itself (sweep.seeds); population must be 1 "
            "in a sweep (use `jaxexo train --population K` for a population of one config)"
        )
    paths = [a.path for a in axes]
    heatmap = tuple(table.get("heatmap", paths[:2]))
    if "heatmap" in table:
        if (
            not isinstance(table["heatmap"], list)
            or len(heatmap) != 2
            or not all(isinstance(h, str) for h in heatmap)
        ):
            raise ConfigError(f"sweep.heatmap: expected two axis names, got {table['heatmap']!r}")
        for h in heatmap:
            if h not in paths:
                raise ConfigError(
                    f"sweep.heatmap: {h!r} is not an axis of this sweep (axes: {', '.join(paths)})"
                )
        if heatmap[0] == heatmap[1]:
            raise ConfigError("sweep.heatmap: needs two different axes")
    top = _int("sweep.top", table.get("top", 5), minimum=1)
    chunk = table.get("chunk_size")
    chunk = None if chunk is None else _int("sweep.chunk_size", chunk, minimum=1)
    budget = table.get("memory_budget")
    budget = None if budget is None else memory_budget(budget, "sweep.memory_budget")
    return Sweep(
        raw=raw,
        table=table,
        axes=axes,
        seeds=seeds,
        members=members,
        groups=group_members(members, seeds),
        heatmap=heatmap,
        top=top,
        chunk_size=chunk,
        memory_budget=budget,
    )


# --------------------------------------------------------------------------------------------
# Validation helpers
# --------------------------------------------------------------------------------------------


def _int(where: str, v: Any, minimum: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(f"{where}: expected an integer, got {v!r}")
    if v < minimum:
        raise ConfigError(f"{where}: must be >= {minimum}, got {v}")
    return v


def _seeds(v: Any) -> tuple[int, ...]:
    if isinstance(v, int) and not isinstance(v, bool):
        n = _int("sweep.seeds", v, minimum=1)
        check_seed(0, "sweep.seeds", n)
        return tuple(range(n))
    if not isinstance(v, list) or not v:
        raise ConfigError(f"sweep.seeds: expected a count or a non-empty list of seeds, got {v!r}")
    seeds = tuple(
        check_seed(_int(f"sweep.seeds[{i}]", s, minimum=0), f"sweep.seeds[{i}]")
        for i, s in enumerate(v)
    )
    if len(set(seeds)) != len(seeds):
        raise ConfigError(f"sweep.seeds: seeds repeat: {list(seeds)}")
    return seeds


def _samples(table: dict, axes) -> int:
    random_axes = any(a.kind == "random" for a in axes)
    if "samples" not in table:
        if random_axes:
            raise ConfigError(
                "sweep.samples: required with [sweep.random] (random draws per grid point)"
            )
        return 1
    if not random_axes:
        raise ConfigError("sweep.samples: only meaningful with [sweep.random] axes")
    return _int("sweep.samples", table["samples"], minimum=1)


# Units, lower case: b; kb .. tb (powers of 1000); kib .. tib (powers of 1024).
_BYTES = {"": 1, "b": 1} | {
    p + unit: base**k for k, p in enumerate("kmgt", 1) for unit, base in (("b", 1000), ("ib", 1024))
}


# A chunk holds at least one agent per CPU device, and one agent of the smallest config takes tens
# of MiB (jaxexo.sweep.plan.agent_bytes): a smaller budget can only be a mistyped unit.
MIN_MEMORY_BUDGET = 64 * 2**20


def memory_budget(v: Any, where: str = "--memory-budget") -> int:
    """A sweep's memory budget (``parse_bytes``) of at least MIN_MEMORY_BUDGET; ConfigError naming
    ``where`` and the bound."""
    n = parse_bytes(v, where)
    if n < MIN_MEMORY_BUDGET:
        raise ConfigError(
            f"{where}: must be at least {MIN_MEMORY_BUDGET // 2**20} MiB (one agent per CPU device "
            f"takes tens of MiB), got {v!r}"
        )
    return n


def parse_bytes(v: Any, where: str = "--memory-budget") -> int:
    """A memory size: a number of bytes or a string such as "512MiB", "4 GiB", "2GB"."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        n, unit = float(v), ""
    elif isinstance(v, str) and (
        m := re.fullmatch(r"\s*([+-]?[0-9]*\.?[0-9]+)\s*([a-zA-Z]*)\s*", v)
    ):
        n, unit = float(m.group(1)), m.group(2).lower()
    else:
        raise ConfigError(f'{where}: expected a size such as "4GiB" or "512MiB", got {v!r}')
    if unit not in _BYTES:
        raise ConfigError(
            f"{where}: unknown unit {unit!r} (use B, KiB, MiB, GiB, TiB, KB, MB, GB, TB)"
        )
    if not math.isfinite(n) or n <= 0:
        raise ConfigError(f"{where}: must be > 0, got {v!r}")
    return int(n * _BYTES[unit])


def _parse_axis(key: Any, kind: str, spec: Any, base: Config) -> Axis:
    where = f"sweep.{kind}.{key}"
    m = _AXIS.fullmatch(key) if isinstance(key, str) else None
    if not m:
        raise ConfigError(
            f'{where}: an axis is named section.field or section.field[i], e.g. "train.lr"'
        )
    section, name, index = m.group(1), m.group(2), m.group(3)
    if section not in SECTIONS:
        raise ConfigError(
            f"{where}: unknown axis: no config section {section!r} (sections: {', '.join(SECTIONS)})"
        )
    obj = getattr(base, section)
    names = [f.name for f in fields(obj)]
    if name not in names:
        raise ConfigError(
            f"{where}: unknown axis: [{section}] has no field {name!r} (known: {', '.join(names)})"
        )
    current = getattr(obj, name)
    if index is not None:
        index = int(index)
        if not isinstance(current, tuple) or not all(isinstance(x, (int, float)) for x in current):
            raise ConfigError(
                f"{where}: {section}.{name} is not a vector of numbers; sweep it whole"
            )
        if index >= len(current):
            raise ConfigError(
                f"{where}: index {index} is out of range ({section}.{name} has {len(current)} elements)"
            )
        current = current[index]
    if kind == "grid":
        if not isinstance(spec, list):
            raise ConfigError(f"{where}: expected a list of values, got {spec!r}")
        if not spec:
            raise ConfigError(f"{where}: empty grid (give at least one value)")
        seen: dict = {}
        for i, v in enumerate(spec):
            k = _value_key(v)
            if k in seen:
                raise ConfigError(
                    f"{where}: the value {format_value(v)} is listed twice (values {seen[k]} and {i}); "
                    "each configuration is trained once, list each value once"
                )
            seen[k] = i
        return Axis(key, section, name, index, kind, values=tuple(spec))
    if not isinstance(spec, dict):
        raise ConfigError(
            f"{where}: expected a table {{ low = ..., high = ..., log = false }} or {{ choices = [...] }}, "
            f"got {spec!r}"
        )
    unknown = sorted(set(spec) - set(RANDOM_KEYS))
    if unknown:
        raise ConfigError(f"{where}.{unknown[0]}: unknown field (known: {', '.join(RANDOM_KEYS)})")
    if "choices" in spec:
        if set(spec) != {"choices"}:
            raise ConfigError(f"{where}: give either choices or a range (low, high), not both")
        if not isinstance(spec["choices"], list) or not spec["choices"]:
            raise ConfigError(
                f"{where}.choices: expected a non-empty list, got {spec['choices']!r}"
            )
        return Axis(key, section, name, index, kind, values=tuple(spec["choices"]))
    for k in ("low", "high"):
        if k not in spec:
            raise ConfigError(f"{where}.{k}: required for a random range")
        v = spec[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ConfigError(f"{where}.{k}: expected a finite number, got {v!r}")
    low, high, log = spec["low"], spec["high"], spec.get("log", False)
    if not isinstance(log, bool):
        raise ConfigError(f"{where}.log: expected true or false, got {log!r}")
    if not low < high:
        raise ConfigError(f"{where}: bad range: low ({low}) must be below high ({high})")
    if log and low <= 0:
        raise ConfigError(f"{where}.low: a log range needs low > 0, got {low}")
    if isinstance(current, bool) or not isinstance(current, (int, float)):
        raise ConfigError(f"{where}: {section}.{name} is not a number; use choices = [...]")
    integer = isinstance(current, int)
    if integer and not (float(low).is_integer() and float(high).is_integer()):
        raise ConfigError(
            f"{where}: {section}.{name} is an integer field; low and high must be integers"
        )
    return Axis(
        key, section, name, index, kind, low=float(low), high=float(high), log=log, integer=integer
    )


def _value_key(v: Any):
    """A hashable key under which equal axis values (1e-3 and 0.001, 1 and 1.0) coincide."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return ("number", float(v))
    return ("value", json.dumps(v, sort_keys=True, default=repr))


def _check_size(axes, samples: int) -> None:
    """Refuse a sweep of more than MAX_CONFIGURATIONS configurations, counted from its axes before
    any is built (building a huge grid's configurations takes minutes: docs/reliability.md)."""
    sizes = [len(a.values) for a in axes if a.kind == "grid"]
    if any(a.kind == "random" for a in axes):
        sizes.append(samples)
    n = math.prod(sizes)
    if n > MAX_CONFIGURATIONS:
        shape = " x ".join(f"{k:,}" for k in sizes)
        raise ConfigError(
            f"sweep.grid: {n:,} configurations ({shape}), more than the {MAX_CONFIGURATIONS:,} a "
            "sweep may have; split it into several sweeps"
        )


def _axes(table: dict, base: Config) -> tuple[Axis, ...]:
    axes = []
    for kind in ("grid", "random"):
        t = table.get(kind, {})
        if not isinstance(t, dict):
            raise ConfigError(f"sweep.{kind}: expected a table of axes, got {t!r}")
        axes += [_parse_axis(k, kind, v, base) for k, v in t.items()]
    paths = [a.path for a in axes]
    for p in paths:
        if paths.count(p) > 1:
            raise ConfigError(
                f"sweep.random.{p}: already a grid axis (an axis is either grid or random)"
            )
    fields_swept = [(a.section, a.field) for a in axes]
    for a in axes:
        if (
            a.index is not None
            and fields_swept.count((a.section, a.field)) > 1
            and any(b.index is None and (b.section, b.field) == (a.section, a.field) for b in axes)
        ):
            raise ConfigError(f"{a.where}: {a.section}.{a.field} is also swept whole")
    if not axes:
        raise ConfigError("sweep.grid: no axes (add [sweep.grid] or [sweep.random] entries)")
    return tuple(axes)


# --------------------------------------------------------------------------------------------
# Expansion and grouping
# --------------------------------------------------------------------------------------------


def _draw(axis: Axis, rng: np.random.Generator):
    if axis.values:
        return axis.values[int(rng.integers(len(axis.values)))]
    if axis.integer:
        return int(rng.integers(int(axis.low), int(axis.high) + 1))
    if axis.log:
        return float(math.exp(rng.uniform(math.log(axis.low), math.log(axis.high))))
    return float(rng.uniform(axis.low, axis.high))


class _Builder:
    """Member configs built from the base config: each axis value is parsed once by its field's
    declared check (the same check a config file's value goes through; fields are parsed
    independently, so replacing one in the parsed base equals parsing the edited table), and the
    whole is cross-checked by ``validate``, whose costly scene checks run once per distinct scene
    (jaxexo.config.consistency). The cost of a member is then a few dataclass replacements."""

    def __init__(self, base: Config, axes):
        self.base, self.axes = base, axes
        self.fields = {}
        for a in axes:
            self.fields.setdefault(a.section, {}).setdefault(a.field, []).append(a)
        self.checks = {s: dict(declared_fields(type(getattr(base, s)))) for s in self.fields}
        self.parsed: dict = {}

    def __call__(self, values: dict) -> Config:
        sections = {}
        for section, by_field in self.fields.items():
            obj, changes = getattr(self.base, section), {}
            for name, axes in by_field.items():
                if axes[0].index is None:
                    v = values[axes[0].path]
                else:
                    v = list(getattr(obj, name))
                    for a in axes:
                        v[a.index] = values[a.path]
                key = (section, name, _value_key(v))
                if key not in self.parsed:
                    self.parsed[key] = self.checks[section][name].check(
                        f"{section}.{name}", copy.deepcopy(v)
                    )
                changes[name] = self.parsed[key]
            sections[section] = dataclasses.replace(obj, **changes)
        cfg = dataclasses.replace(self.base, **sections)
        validate(cfg)
        return cfg


def _expand(raw: dict, base: Config, axes, samples: int, sample_seed: int) -> tuple[Member, ...]:
    grid = [a for a in axes if a.kind == "grid"]
    rand = [a for a in axes if a.kind == "random"]
    rng = np.random.default_rng(sample_seed)
    build = _Builder(base, axes)
    members = []
    for combo in itertools.product(*(a.values for a in grid)):
        for _ in range(samples if rand else 1):
            values = dict(zip((a.path for a in grid), combo))
            values.update((a.path, _draw(a, rng)) for a in rand)
            values = {a.path: values[a.path] for a in axes}  # in the order written
            try:
                cfg = build(values)
            except ConfigError as e:
                first = next(
                    (a for a in axes if str(e).startswith(f"{a.section}.{a.field}")), axes[0]
                )
                raise ConfigError(
                    f"{first.where}: configuration {len(members)} "
                    f"({', '.join(f'{k}={format_value(v)}' for k, v in values.items())}): {e}"
                ) from None
            members.append(Member(len(members), values, cfg))
    return tuple(members)


def group_members(members, seeds) -> tuple[Group, ...]:
    """Group configurations by static settings (jaxexo.config.static_settings), in order of first
    appearance; within a group, agents run configuration by configuration, every seed of each."""
    by_sig: dict = {}
    for m in members:
        by_sig.setdefault(static_settings(m.config), []).append(m.config_id)
    return tuple(
        Group(g, tuple(ids), tuple((c, s) for c in ids for s in seeds))
        for g, ids in enumerate(by_sig.values())
    )
