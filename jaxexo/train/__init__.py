"""The vectorised TD(lambda) trainer (needs the ``train`` extra)."""

from jaxexo.train.trainer import METRICS, Hyperparams, Trainer, TrainState, make_train

__all__ = ["make_train", "Trainer", "TrainState", "Hyperparams", "METRICS"]
