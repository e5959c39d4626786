"""Reading a config: a TOML file or a parsed table becomes a validated ``Config``, each field parsed
by its declared check, unknown fields and sections refused by name, the whole cross-checked
(jaxexo.config.consistency). A sweep file's [sweep] table is removed by jaxexo.sweep.spec first.
"""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path
from typing import Any

from jaxexo.config.checks import ConfigError
from jaxexo.config.consistency import validate
from jaxexo.config.declarations import declared_fields
from jaxexo.config.input_files import check_path_type, read_text_input
from jaxexo.config.obstacles import default_obstacles
from jaxexo.config.sections import SECTION_CLASSES, SECTIONS, Config

# Sections that other commands read; a train config refuses them, saying where they belong.
OTHER_COMMANDS = {
    "sweep": "it is read by jaxexo sweep (a sweep file, see configs/sweeps/*.toml)",
    "eval": "no command reads it: jaxexo eval takes its settings as options (--n, --scenarios, "
    "--against), and training's greedy evaluation size is train.eval_episodes",
}


def _section(cls, path: str, raw: Any) -> Any:
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a table, got {raw!r}")
    specs = dict(declared_fields(cls))
    unknown = sorted(set(raw) - set(specs))
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(sorted(specs))})")
    return cls(**{k: specs[k].check(f"{path}.{k}", v) for k, v in raw.items()})


def config_from_dict(raw: dict) -> Config:
    """Build and validate a Config from a parsed TOML table."""
    if not isinstance(raw, dict):
        raise ConfigError(f"config: expected a table, got {raw!r}")
    for name in raw:
        if name in OTHER_COMMANDS:
            raise ConfigError(
                f"{name}: a [{name}] section does not belong in a train config; "
                f"{OTHER_COMMANDS[name]}"
            )
    unknown = sorted(set(raw) - set(SECTIONS))
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown section (known: {', '.join(sorted(SECTIONS))})")
    parts = {s: _section(SECTION_CLASSES[s], s, raw.get(s, {})) for s in SECTIONS}
    if not parts["layout"].obstacles:
        parts["layout"] = dataclasses.replace(parts["layout"], obstacles=default_obstacles())
    cfg = Config(**parts)
    validate(cfg)
    return cfg


def load_config(path: str | Path) -> Config:
    """Read, parse and validate a TOML config file (a regular file of at most MAX_TEXT_BYTES,
    jaxexo.config.input_files; UTF-8, a leading byte-order mark allowed)."""
    path = check_path_type(path, "config")
    text = read_text_input(path, "config")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from None
    try:
        return config_from_dict(raw)
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def packaged_config(name: str = "default") -> Path:
    """A config shipped inside the package: "default" (jaxexo/config/default.toml) or "thesis/<model>"
    (jaxexo/config/thesis/<model>.toml). The same file however jaxexo is installed; the repository's
    configs/ holds byte-equal copies (tests/test_config_roundtrip.py)."""
    path = Path(__file__).resolve().parent / f"{name}.toml"
    if not path.is_file():
        raise ConfigError(f"{name}: no packaged config {path}")
    return path
