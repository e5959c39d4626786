"""Writing a resolved Config back to TOML (tomllib only reads), so a run directory records exactly
what it trained with. Every field is written from its declaration (jaxexo.config.sections), and
``load_config`` of the text gives back an equal Config (tests/test_config_roundtrip.py)."""

from __future__ import annotations

import json
import math

from jaxexo.config.sections import SECTION_CLASSES, SECTIONS, Config, to_toml_values


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(int(v))
    if isinstance(v, float):
        v = float(v)  # np.float64 is a float whose repr is "np.float64(...)"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if math.isnan(v):
            return "nan"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def config_to_toml(cfg: Config) -> str:
    lines = ["# Resolved jaxexo configuration (metres, radians, steps)."]
    for section in SECTIONS:
        assert SECTION_CLASSES[section] is type(getattr(cfg, section))
        lines += ["", f"[{section}]"]
        for name, v in to_toml_values(getattr(cfg, section)):
            if (
                isinstance(v, list) and v and isinstance(v[0], dict)
            ):  # the obstacle list, one per line
                lines += [f"{name} = ["] + [f"  {_value(x)}," for x in v] + ["]"]
            else:
                lines.append(f"{name} = {_value(v)}")
    return "\n".join(lines) + "\n"
