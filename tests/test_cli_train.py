"""``jaxexo train`` through the CLI (subprocesses)."""

from __future__ import annotations

import json
import os

import pytest

from jaxexo.config import load_config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.policy_file import load_policy

from conftest import run_cli

jax = pytest.importorskip("jax")


pytestmark = pytest.mark.slow  # subprocess CLI runs

from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)

# --------------------------------------------------------------------------------------------
# CLI
# --------------------------------------------------------------------------------------------


def test_cli_train_writes_the_run_directory(tiny_reference):
    """``python -m jaxexo.cli train CONFIG --out DIR --quiet --seed 3``: the session's reference run
    (on one CPU device, so that the in-process driver tests can compare with it bit for bit)."""
    ref, out = tiny_reference, tiny_reference["run"]
    stdout, stderr = ref["stdout"], ref["stderr"]
    assert_run_files(out)
    assert load_config(out / "config.toml") == load_config(ref["cfg_path"]) == ref["cfg"]
    assert len((out / "metrics.jsonl").read_text().splitlines()) == 3
    res = json.loads((out / "eval.json").read_text())
    assert (
        res["env_steps"] == TINY_UPDATES * TINY_N * TINY_T
        and res["seed"] == SEED
        and res["devices"] == 1
    )
    assert sum(v["n"] for v in res["by_obstacle"].values()) == TINY_TRAIN["eval_episodes"]
    assert load_policy(out / "policy.npz").num_actions == 36
    assert f"{res['env_steps']:,} env steps" in stdout and "policy.npz" in stdout
    assert "\r" not in stderr and "it/s" not in stderr  # --quiet: no progress bar


def test_cli_train_bad_config_exits_2_naming_the_field(tmp_path):
    cfg_path = tmp_path / "bad.toml"
    cfg_path.write_text('[train]\ncontrol = "sarsa"\n')
    r = run_cli("train", cfg_path, "--out", tmp_path / "run", "--quiet", timeout=120)
    assert r.returncode == 2
    assert "train.control" in r.stderr and "sarsa" in r.stderr


def test_cli_train_loads_its_programs_from_the_compilation_cache(tiny_reference, tmp_path):
    """``jaxexo train`` keeps its compiled programs in $JAXEXO_COMPILATION_CACHE: after a run with
    another learning rate (a pytree leaf), a run of the same static settings writes no new program (the
    cache writes only what it compiles), reads every one (their access times move), and exports the
    same bytes as the session's reference run of its config, which compiled its own programs (cache
    "off": test_compilation_cache_setting)."""
    from train_helpers import tiny_config

    cache = tmp_path / "cache"
    env = {
        k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR")
    }
    env.update(
        XLA_FLAGS="--xla_force_host_platform_device_count=1", JAXEXO_COMPILATION_CACHE=str(cache)
    )

    def train(name, cfg):
        path = tmp_path / f"{name}.toml"
        path.write_text(config_to_toml(cfg))
        r = run_cli(
            "train", path, "--out", tmp_path / name, "--quiet", "--seed", SEED, env=env, timeout=600
        )
        assert r.returncode == 0, r.stderr[-3000:]
        return tmp_path / name

    def entries(suffix):
        return {p.name: p.stat().st_mtime_ns for p in cache.iterdir() if p.name.endswith(suffix)}

    train("other_lr", tiny_config(lr=3e-3))
    programs, read = entries("-cache"), entries("-atime")
    assert {n.split("-")[0] for n in programs} >= {
        "jit_run",
        "jit_init",
        "jit_validate",
        "jit_rollouts",
    }, programs
    assert any(n.startswith("jit_run-") for n in read), read
    assert tiny_reference["cfg"] == tiny_config()
    again = train("again", tiny_config())
    assert entries("-cache") == programs
    later = entries("-atime")
    assert all(
        later[n] > t for n, t in read.items() if n.split("-")[0] in ("jit_run", "jit_validate")
    ), (read, later)
    assert (again / "policy.npz").read_bytes() == (
        tiny_reference["run"] / "policy.npz"
    ).read_bytes()


def test_compilation_cache_setting(monkeypatch, tmp_path):
    """use_compilation_cache: "off" leaves JAX's setting alone, a directory that cannot be made and a
    symbolic link jaxexo did not make are refused with a warning (the run compiles as without a
    cache), a usable one is created and set."""
    from jax.experimental.compilation_cache import compilation_cache as cc

    from jaxexo.train.devices import CACHE_ENV, use_compilation_cache

    names = ("jax_compilation_cache_dir", "jax_compilation_cache_max_size")
    old = {n: getattr(jax.config, n) for n in names}
    try:
        jax.config.update("jax_compilation_cache_dir", None)
        monkeypatch.setenv(CACHE_ENV, "off")
        assert use_compilation_cache() is None and jax.config.jax_compilation_cache_dir is None
        blocker = tmp_path / "a_file"
        blocker.write_text("x")
        monkeypatch.setenv(CACHE_ENV, str(blocker / "xla"))
        with pytest.warns(UserWarning, match=CACHE_ENV):
            assert use_compilation_cache() is None
        assert jax.config.jax_compilation_cache_dir is None
        elsewhere = tmp_path / "elsewhere"
        elsewhere.mkdir()
        (tmp_path / "link").symlink_to(elsewhere, target_is_directory=True)
        monkeypatch.setenv(CACHE_ENV, str(tmp_path / "link"))
        with pytest.warns(UserWarning, match="symbolic link"):
            assert use_compilation_cache() is None
        assert jax.config.jax_compilation_cache_dir is None and not any(elsewhere.iterdir())
        monkeypatch.setenv(CACHE_ENV, str(tmp_path / "xla"))
        assert (
            use_compilation_cache() == str(tmp_path / "xla") == jax.config.jax_compilation_cache_dir
        )
        assert (tmp_path / "xla").is_dir() and jax.config.jax_compilation_cache_max_size > 0
    finally:
        for n, v in old.items():
            jax.config.update(n, v)
        cc.reset_cache()
