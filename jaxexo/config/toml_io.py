"""Writing a resolved Config back to TOML (tomllib only reads), so a run directory records exactly
what it trained with. ``load_config(write)`` gives back an equal Config."""

from __future__ import annotations

import dataclasses
import json
import math

from jaxexo.config import Config


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _obstacle(o) -> dict:
    d = {"kind": o.kind, "weight": o.weight}
    if o.kind in ("rectangle", "triangle", "half_ellipse", "profile"):
        d["width"] = list(o.width)
        d["height"] = list(o.height)
    if o.kind == "profile":
        d["points"] = [list(p) for p in o.points]
    return d


def config_to_toml(cfg: Config) -> str:
    lines = ["# Resolved jaxexo configuration (metres, radians, steps)."]
    for section in ("env", "kinematics", "reward", "train", "device"):
        lines += ["", f"[{section}]"]
        for f in dataclasses.fields(getattr(cfg, section)):
            lines.append(f"{f.name} = {_value(getattr(getattr(cfg, section), f.name))}")
    lines += ["", "[layout]", "obstacles = ["]
    lines += [f"  {_value(_obstacle(o))}," for o in cfg.layout.obstacles]
    lines.append("]")
    for f in dataclasses.fields(cfg.layout):
        if f.name != "obstacles":
            lines.append(f"{f.name} = {_value(getattr(cfg.layout, f.name))}")
    for name, table in cfg.extra.items():
        lines += ["", f"[{name}]"] + [f"{k} = {_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"
