"""The resolved form of every shipped config (configs/**.toml and the package's copies, sweeps
member by member) and of the tests' raw configs, for tests/test_reliability_inputs.py: a change of
the schema's declared defaults must not change what any of them means.

``python tests/resolved_snapshot.py`` rewrites tests/data/resolved_configs.json; it was generated
from main (9514f99) before the declared defaults became the default model's settings."""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SNAPSHOT = ROOT / "tests" / "data" / "resolved_configs.json"


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def resolved() -> dict:
    from jaxexo.config import load_config
    from jaxexo.config.toml_io import config_to_toml
    from jaxexo.sweep.spec import load_sweep

    from jaxexo.config import Config, config_from_dict

    # "schema_defaults": what Config() (and an empty config) meant on main: the tests' raw configs
    # are stated on top of it (conftest.legacy_raw), so that they keep their meaning.
    out = {"configs": {}, "sweeps": {}, "schema_defaults": config_to_toml(Config()),
           "empty": config_to_toml(config_from_dict({}))}
    for base in (ROOT / "configs", ROOT / "jaxexo" / "config"):
        for path in sorted(base.rglob("*.toml")):
            name = str(path.relative_to(ROOT))
            if "sweeps" in path.parts:
                sweep = load_sweep(path)
                out["sweeps"][name] = [_digest(config_to_toml(m.config)) for m in sweep.members]
            else:
                out["configs"][name] = config_to_toml(load_config(path))
    return out


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    SNAPSHOT.write_text(json.dumps(resolved(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {SNAPSHOT}")
