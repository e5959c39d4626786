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
# Fields declared after the snapshot was taken, at the value that means what every config meant
# before them (the wearer's costs: 0 is the thesis reward). A config that states them so, or a
# resolved text that has them so, means what it meant.
# train.population: 1 is one agent, what every config trained before it.
# env.floor_clearance: 0 is no floor rule, the shield before it.
ADDED_SINCE = {
    "reward": {"lift_cost": 0.0, "time_cost": 0.0, "turn_cost": 0.0},
    "train": {"population": 1},
    "env": {"floor_clearance": 0.0},
}
# Configs deliberately redefined since: the default model (a new reward and mid-goal) and
# the sweeps built on it. Their meaning is the default's (tests/test_config_roundtrip.py).
# quick.toml (both copies): 32 minibatches per update since 2026-12-02 (4 learned at only some seeds).
# Since 2026-12-04 the default's swing ends on the floor (env.goal_tolerance, env.floor_clearance),
# and every sweep built on the default with it.
REDEFINED = {
    "configs/default.toml",
    "jaxexo/config/default.toml",
    "configs/sweeps/backward.toml",
    "configs/sweeps/lr_lambda.toml",
    "configs/sweeps/reward_weights.toml",
    "configs/sweeps/smoke.toml",
    "configs/quick.toml",
    "jaxexo/config/quick.toml",
}


# The drives' settings declared since ([device], role "setting"): they time a swing for a device,
# they do not change what a config trains (a policy file that lacks them reads the defaults).
DEVICE_ADDED = ("joint_jerk", "tracking_headroom")


def without_added(text: str) -> str:
    """A resolved config's text without the ADDED_SINCE lines that hold their neutral value and
    without the DEVICE_ADDED lines."""
    drop = {f"{k} = {v!r}" for fields in ADDED_SINCE.values() for k, v in fields.items()}
    return "\n".join(
        line
        for line in text.split("\n")
        if line not in drop and not line.startswith(tuple(f"{k} = " for k in DEVICE_ADDED))
    )


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def resolved() -> dict:
    from jaxexo.config import Config, config_from_dict, load_config
    from jaxexo.config.toml_io import config_to_toml
    from jaxexo.sweep.spec import load_sweep

    # "schema_defaults": what Config() (and an empty config) meant on main: the tests' raw configs
    # are stated on top of it (conftest.legacy_raw), so that they keep their meaning.
    out = {
        "configs": {},
        "sweeps": {},
        "schema_defaults": config_to_toml(Config()),
        "empty": config_to_toml(config_from_dict({})),
    }
    for base in (ROOT / "configs", ROOT / "jaxexo" / "config"):
        for path in sorted(base.rglob("*.toml")):
            name = str(path.relative_to(ROOT))
            if "sweeps" in path.parts:
                sweep = load_sweep(path)
                out["sweeps"][name] = [
                    _digest(without_added(config_to_toml(m.config))) for m in sweep.members
                ]
            else:
                out["configs"][name] = without_added(config_to_toml(load_config(path)))
    return out


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    SNAPSHOT.write_text(json.dumps(resolved(), indent=1, sort_keys=True) + "\n")
    print(f"wrote {SNAPSHOT}")
