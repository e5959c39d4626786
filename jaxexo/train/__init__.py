"""The vectorised TD(lambda) trainer (needs the ``train`` extra).

The trainer's names are loaded on first use, so that ``jaxexo.train.devices`` can set the number of
CPU devices before anything imports JAX."""

import importlib

__all__ = ["make_train", "Trainer", "TrainState", "Hyperparams", "METRICS"]


def __getattr__(name):
    if name in __all__:
        return getattr(importlib.import_module("jaxexo.train.trainer"), name)
    raise AttributeError(f"module 'jaxexo.train' has no attribute {name!r}")
