"""A Config seen as the environment's parameters (``param_values``, and its NumPy, plain-float and,
in jaxexo.env.params, JAX views), and ``test_config``, the config evaluated on the five thesis
obstacles (Table 3.1). NumPy-only: the physics is given these values, it never reads a Config.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from jaxexo.config.declarations import declared_fields
from jaxexo.config.obstacles import named_spec
from jaxexo.config.sections import ENV_SECTIONS, SECTION_CLASSES, Config
from jaxexo.physics.actions import action_directions
from jaxexo.physics.scenarios import TEST_KINDS


def param_values(cfg: Config) -> dict[str, np.ndarray]:
    """Every environment parameter as a NumPy value (float32, int32 or bool), by EnvParams field name.

    Derived from the config's declarations: each leaf field of ENV_SECTIONS becomes one or more
    parameters (``FieldSpec.params``), plus the fixed action set (thesis 2.1). ``EnvParams`` is built
    from these names (jaxexo.env.params); NumPy code uses the values as they are."""
    out = {"directions": np.asarray(action_directions(), dtype=np.float32)}
    for section in ENV_SECTIONS:
        obj = getattr(cfg, section)
        for name, spec in declared_fields(SECTION_CLASSES[section]):
            if spec.leaf:
                out.update(spec.params(name, getattr(obj, name), cfg))
    return out


# The NumPy and plain-float views' one record: a frozen dataclass whose fields are param_values'
# names (those of EnvParams), derived here from the declarations rather than written out again.
ParamView = dataclasses.make_dataclass(
    "ParamView", [(k, Any) for k in param_values(Config())], frozen=True, slots=True, kw_only=True
)
ParamView.__module__ = __name__
ParamView.__doc__ = """The environment parameters of a config outside JAX, one field per name of
``param_values`` (EnvParams's): NumPy values (``numpy_params``) or Python floats (``scalar_params``).
Changed with ``dataclasses.replace``."""


def numpy_params(cfg: Config) -> ParamView:
    """The environment parameters as NumPy arrays, attribute-accessible like EnvParams."""
    return ParamView(**param_values(cfg))


def scalar_params(cfg: Config) -> ParamView:
    """The transition constants as Python floats (for ``xp=transition.scalar``); vectors become tuples,
    and the parameters that are not float32 scalars or vectors None.

    Values are rounded through float32 first, so that the scalar loop starts from exactly the
    constants the float32 JAX environment uses."""
    out = {}
    for k, v in param_values(cfg).items():
        scalar = v.dtype == np.float32 and v.ndim <= 1
        out[k] = None if not scalar else float(v) if v.ndim == 0 else tuple(float(x) for x in v)
    return ParamView(**out)


def test_config(cfg: Config) -> Config:
    """The training config with the layout's obstacle mixture replaced by the five thesis obstacles
    and all three pivot conditions (same jitter, start shifts and step lengths)."""
    lay = dataclasses.replace(
        cfg.layout, obstacles=tuple(named_spec(k) for k in TEST_KINDS), pivot=(1.0, 1.0, 1.0)
    )
    lay = dataclasses.replace(lay, terrain=None)
    env = dataclasses.replace(cfg.env, max_vertices=0)
    return dataclasses.replace(cfg, layout=lay, env=env)
