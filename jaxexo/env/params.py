"""Environment parameters as a flax.struct pytree, built from a validated Config.

Every field here is a pytree leaf (vmappable: reward weights and constants, kinematic constants, the
layout distribution). The fields are not listed a second time: they are the names that
``jaxexo.config.param_values`` derives from the config declarations (jaxexo.config.schema,
each leaf field of [env], [kinematics], [reward], [layout], plus the action directions). Shapes (the
number of outline vertices, shape-descriptor points, obstacle kinds, the observation mode) are fixed
by the arrays themselves or by the ExoStepEnv instance.
"""

from __future__ import annotations


import jax.numpy as jnp
from flax import struct

from jaxexo.config import Config, param_values

# The names and their order do not depend on the config's values, so the default config fixes them.
PARAM_NAMES = tuple(param_values(Config()))


def _from_config(cls, cfg: Config):
    # One list of values (jaxexo.physics.dynamics.param_values) for the JAX and the NumPy side.
    return cls(**{k: jnp.asarray(v) for k, v in param_values(cfg).items()})


EnvParams = struct.dataclass(type("EnvParams", (), {
    "__annotations__": {name: jnp.ndarray for name in PARAM_NAMES},
    "from_config": classmethod(_from_config), "__module__": __name__,
    "__doc__": "Environment parameters (pytree leaves), one per name of param_values."}))
