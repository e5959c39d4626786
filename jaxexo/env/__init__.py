"""The JAX stepping environment (needs the ``train`` extra: jax, flax)."""

from jaxexo.env.exo_step import (
    LENGTH_SCALE,
    NUM_ACTIONS,
    EnvState,
    ExoStepEnv,
    Layout,
)
from jaxexo.env.params import EnvParams

__all__ = ["ExoStepEnv", "EnvParams", "EnvState", "Layout", "NUM_ACTIONS", "LENGTH_SCALE"]
