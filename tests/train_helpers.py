"""Shared pieces of the training tests (test_trainer, test_driver, test_policy_file, test_network,
test_train_config, test_cli_train): the tiny config (defined in conftest, jax-free, and shared with
test_reliability) and tree helpers (the uninterrupted ``jaxexo train`` reference run of the tiny
config is conftest's ``tiny_reference``).

JAX compile time dominates these tests (a trainer update takes 5-6 s to compile on two CPU cores,
most of it the environment step), so:
- the runs are tiny and share one config (``tiny``) wherever they can;
- the session's persistent compilation cache (conftest) lets runs reuse programs that other tests,
  other workers and CLI subprocesses compiled;
- the uninterrupted reference run (conftest's ``tiny_reference``) is made once per session, whichever
  xdist worker asks first, and shared by the driver, reliability and CLI tests.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict, load_config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.policy_file import FORMAT_VERSION, PolicyFileError, load_policy

from conftest import (  # noqa: F401 (the shared tiny config, for the star imports)
    FIXED_LAYOUT,
    REWARD,
    ROOT,
    SEED,
    TINY_N,
    TINY_T,
    TINY_TRAIN,
    TINY_UPDATES,
    legacy_raw,
    tiny_config,
    tiny_raw,
)

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.train import driver, run_dir  # noqa: E402
from jaxexo.train.evaluate import HELD_OUT, TEST_KINDS, make_rollout  # noqa: E402
from jaxexo.train.trainer import METRICS, Hyperparams, Trainer, make_train  # noqa: E402

COL = {m: i for i, m in enumerate(METRICS)}


def metric_array(m) -> np.ndarray:
    """UpdateMetrics [..., U] as one host array [..., U, len(METRICS)], its columns in METRICS order."""
    return np.stack([np.asarray(getattr(m, k)) for k in METRICS], axis=-1)


def assert_run_files(out) -> None:
    """A finished run directory ``out`` holds every file of a run."""
    for name in (
        "config.toml",
        "metrics.jsonl",
        "policy.npz",
        "training_curve.png",
        "eval.json",
        run_dir.CHECKPOINT,
        run_dir.BOOKKEEPING,
    ):
        assert (out / name).is_file(), name


def leaves(tree) -> list[np.ndarray]:
    return [np.asarray(x) for x in jax.tree.leaves(tree)]


def trees_equal(a, b) -> bool:
    la, lb = leaves(a), leaves(b)
    return len(la) == len(lb) and all(
        x.dtype == y.dtype and np.array_equal(x, y) for x, y in zip(la, lb)
    )


def all_finite(tree) -> bool:
    return all(np.all(np.isfinite(x)) for x in leaves(tree) if np.issubdtype(x.dtype, np.floating))


def avals(tree) -> list[tuple]:
    return [(x.shape, x.dtype, x.weak_type) for x in jax.tree.leaves(tree)]


@pytest.fixture(scope="module")
def tiny():
    """The shared tiny config's trainer with its jitted init and run (the driver's programs too)."""
    cfg = tiny_config()
    trainer = Trainer(cfg)
    return {
        "cfg": cfg,
        "trainer": trainer,
        "hyper": Hyperparams.from_config(cfg),
        "init": jax.jit(trainer.init),
        "run": jax.jit(trainer.run, static_argnums=2),
    }


def random_params(net, obs_dim: int, seed: int):
    """The network's parameter tree (flax's names and shapes) with random values everywhere,
    LayerNorm scales and biases included (not the initial ones: zero biases, unit scales)."""
    rng = np.random.default_rng(seed)
    shapes = jax.eval_shape(net.init, jax.random.PRNGKey(0), jnp.zeros((1, obs_dim)))
    return jax.tree.map(
        lambda s: (rng.normal(size=s.shape) * 0.5 + (1.0 if s.ndim == 1 else 0.0)).astype(s.dtype),
        shapes,
    )


def _npz(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}
