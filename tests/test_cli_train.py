"""``jaxexo train`` through the CLI (subprocesses)."""

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

from conftest import ROOT, jax_compilation_cache

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.train import driver, run_files  # noqa: E402
from jaxexo.train.evaluate import HELD_OUT, TEST_KINDS, make_rollout  # noqa: E402
from jaxexo.train.trainer import METRICS, Hyperparams, Trainer, make_train  # noqa: E402
pytestmark = pytest.mark.slow   # subprocess CLI runs

from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)
from train_helpers import _cli_cmd


# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------


def test_cli_train_writes_the_run_directory(train_background):
    """``python -m jaxexo.cli train CONFIG --out DIR --quiet --seed 3``: the background reference run
    (on one CPU device, so that the in-process driver tests can compare with it bit for bit)."""
    ref = train_background["reference"]
    stdout, stderr = ref.wait()
    for name in ("config.toml", "metrics.jsonl", "policy.npz", "training_curve.png", "eval.json",
                 run_files.CHECKPOINT, run_files.BOOKKEEPING):
        assert (ref.out / name).is_file(), name
    assert load_config(ref.out / "config.toml") == load_config(ref.cfg_path) == ref.cfg
    assert len((ref.out / "metrics.jsonl").read_text().splitlines()) == 3
    res = json.loads((ref.out / "eval.json").read_text())
    assert res["env_steps"] == TINY_UPDATES * TINY_N * TINY_T and res["seed"] == SEED and res["devices"] == 1
    assert sum(v["n"] for v in res["by_obstacle"].values()) == TINY_TRAIN["eval_episodes"]
    assert load_policy(ref.out / "policy.npz").num_actions == 36
    assert f"{res['env_steps']:,} env steps" in stdout and "policy.npz" in stdout
    assert "\r" not in stderr and "it/s" not in stderr   # --quiet: no progress bar


def test_cli_train_bad_config_exits_2_naming_the_field(tmp_path):
    cfg_path = tmp_path / "bad.toml"
    cfg_path.write_text('[train]\ncontrol = "sarsa"\n')
    r = subprocess.run(_cli_cmd("train", cfg_path, "--out", tmp_path / "run", "--quiet"), capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2
    assert "train.control" in r.stderr and "sarsa" in r.stderr
