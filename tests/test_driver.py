"""The training driver (jaxexo.train.driver): run directory, bit-identical resume after an interrupt,
eval.json, the exported policy, refusals to overwrite or mix runs. Compared with the session's
``jaxexo train`` reference run (conftest's ``tiny_reference``)."""

from __future__ import annotations

import json
import shutil
import tomllib

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict, load_config
from jaxexo.storage.policy_file import load_policy

jax = pytest.importorskip("jax")

from jaxexo.train import checkpoints, driver, run_dir  # noqa: E402
from jaxexo.train.evaluate import HELD_OUT, TEST_KINDS  # noqa: E402

pytestmark = pytest.mark.slow  # training runs and a background ``jaxexo train`` subprocess

from conftest import metrics_without_clock
from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)
from train_helpers import _npz

# --------------------------------------------------------------------------------------------
# The driver: resume, eval.json, policy export
# --------------------------------------------------------------------------------------------


class _Interrupt:
    """Patches checkpoints.checkpoint_write to raise KeyboardInterrupt on its ``at``-th call (calls go
    checkpoint, bookkeeping, checkpoint, bookkeeping, ... one pair per finished chunk)."""

    def __init__(self, at: int):
        self.at, self.calls = at, 0
        self.real = checkpoints.checkpoint_write

    def __call__(self, path, data):
        self.calls += 1
        if self.calls == self.at:
            raise KeyboardInterrupt
        return self.real(path, data)


def _interrupted_then_resumed(cfg, out, at: int) -> dict:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(checkpoints, "checkpoint_write", _Interrupt(at))
        with pytest.raises(KeyboardInterrupt):
            driver.run_training(cfg, out, seed=SEED, progress=False, eval_episodes=20)
    before = {
        "book": json.loads((out / run_dir.BOOKKEEPING).read_text()),
        "metric_lines": len((out / "metrics.jsonl").read_text().splitlines()),
        "policy": (out / "policy.npz").exists(),
    }
    res = driver.run_training(cfg, out, seed=SEED, resume=True, progress=False, eval_episodes=20)
    return {"before": before, "result": res}


@pytest.fixture(scope="module")
def driver_runs(tiny_reference, tmp_path_factory):
    """A 6-update run in 3 chunks of 2, run straight through (by the CLI, in the background), and
    the same run here, killed while saving the checkpoint of chunk 2 (its metrics line already
    written) and resumed."""
    cfg = tiny_config()
    part = tmp_path_factory.mktemp("runs") / "part"
    resumed = _interrupted_then_resumed(cfg, part, at=3)
    full = tiny_reference["run"]
    assert load_config(full / "config.toml") == cfg
    res_full = json.loads((full / "eval.json").read_text())
    return {"cfg": cfg, "full": full, "part": part, "res_full": res_full, **resumed}


def _counters(path) -> list[dict]:
    """The one agent's metrics rows, without the clock."""
    return [r["members"][0] for r in metrics_without_clock(path)]


@pytest.mark.parametrize("which", ["full", "part"])
def test_run_directory_is_complete(driver_runs, which):
    out = driver_runs[which]
    assert_run_files(out)
    assert load_config(out / "config.toml") == driver_runs["cfg"]
    rows = _counters(out / "metrics.jsonl")
    assert [r["chunk"] for r in rows] == [1, 2, 3]
    assert [r["updates"] for r in rows] == [2, 4, 6]
    assert [r["env_steps"] for r in rows] == [k * 2 * TINY_N * TINY_T for k in (1, 2, 3)]
    assert all(0.0 <= r["validation_success_raw"] <= 1.0 for r in rows)
    book = json.loads((out / run_dir.BOOKKEEPING).read_text())
    assert book["chunks_done"] == 3 and book["seed"] == SEED
    assert (out / "training_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_resume_is_bit_identical(driver_runs):
    full, part = driver_runs["full"], driver_runs["part"]
    before = driver_runs["before"]
    # The interruption happened where intended: chunk 1 saved, chunk 2's metrics line written but
    # its checkpoint not, no policy yet.
    assert (
        before["book"]["chunks_done"] == 1 and before["metric_lines"] == 2 and not before["policy"]
    )
    assert (full / run_dir.CHECKPOINT).read_bytes() == (part / run_dir.CHECKPOINT).read_bytes()
    pf, pp = _npz(full / "policy.npz"), _npz(part / "policy.npz")
    assert sorted(pf) == sorted(pp) and len(pf) >= 7
    for k in pf:
        assert pf[k].dtype == pp[k].dtype and np.array_equal(pf[k], pp[k]), k
    assert _counters(full / "metrics.jsonl") == _counters(part / "metrics.jsonl")
    drop = lambda r: {k: v for k, v in r.items() if k != "train_seconds"}  # noqa: E731
    assert drop(driver_runs["res_full"]) == drop(driver_runs["result"])
    assert drop(json.loads((part / "eval.json").read_text())) == drop(driver_runs["result"])


def test_resume_after_an_interrupt_between_checkpoint_and_bookkeeping(driver_runs, tmp_path):
    """Stopped after writing chunk 2's checkpoint but before its readable bookkeeping copy (stale:
    chunk 1's): the run resumes from that checkpoint and ends as the uninterrupted one (when the
    bookkeeping was a separate file that resume read, it lost a metrics row)."""
    out = tmp_path / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(checkpoints, "checkpoint_write", _Interrupt(4))
        with pytest.raises(KeyboardInterrupt):
            driver.run_training(
                driver_runs["cfg"], out, seed=SEED, progress=False, eval_episodes=20
            )
    driver.run_training(
        driver_runs["cfg"], out, seed=SEED, resume=True, progress=False, eval_episodes=20
    )
    assert _counters(driver_runs["full"] / "metrics.jsonl") == _counters(out / "metrics.jsonl")
    assert (driver_runs["full"] / run_dir.CHECKPOINT).read_bytes() == (
        out / run_dir.CHECKPOINT
    ).read_bytes()


def test_eval_json(driver_runs):
    res = json.loads((driver_runs["full"] / "eval.json").read_text())
    for key in (
        "accuracy",
        "success_raw",
        "success",
        "by_obstacle",
        "by_pivot",
        "episodes",
        "env_steps",
        "train_seconds",
        "held_out",
    ):
        assert key in res, key
    assert set(res["by_obstacle"]) == set(TEST_KINDS) and len(TEST_KINDS) == 5
    assert set(res["by_pivot"]) == {"agent", "obstacle", "between"}
    assert sum(v["n"] for v in res["by_obstacle"].values()) == 20
    assert sum(v["n"] for v in res["by_pivot"].values()) == 20
    assert res["held_out"]["n"] == sum(res["by_obstacle"][k]["n"] for k in HELD_OUT)
    for fig in [res, res["held_out"], *res["by_obstacle"].values(), *res["by_pivot"].values()]:
        assert 0.0 <= fig["success_raw"] <= fig["accuracy"] <= 1.0
    assert res["success"] == res["success_raw"]  # the old name, kept for existing readers
    assert res["env_steps"] == TINY_UPDATES * TINY_N * TINY_T
    ck = json.loads((driver_runs["full"] / "metrics.jsonl").read_text().splitlines()[-1])[
        "members"
    ][0]
    assert res["episodes"] == ck["episodes"]
    assert res["train_seconds"] > 0 and res["seed"] == SEED


def test_exported_policy_matches_the_checkpoint(driver_runs, tiny):
    """policy.npz holds the checkpoint's selected (best validation) parameters, computing the same Q."""
    from flax import serialization

    cfg, full = driver_runs["cfg"], driver_runs["full"]
    trainer, hyper = tiny["trainer"], tiny["hyper"]
    template = tiny["init"](jax.random.PRNGKey(0), hyper)
    from jaxexo.storage.checkpoint import unpack_checkpoint

    agents = jax.tree.map(lambda x: np.asarray(x)[None], template)  # one agent: K = 1
    saved = serialization.from_bytes(
        {"state": agents, "best_params": agents.params},
        unpack_checkpoint((full / run_dir.CHECKPOINT).read_bytes(), "ckpt"),
    )
    saved = jax.tree.map(lambda x: x[0], saved)
    assert int(saved["state"].update) == TINY_UPDATES
    pol = load_policy(full / "policy.npz")
    assert pol.metadata["layer_norm"] is True and pol.metadata["layers"] == [
        trainer.env.obs_dim,
        32,
        32,
        36,
    ]
    assert (
        config_from_dict(tomllib.loads(pol.metadata["config_toml"])) == cfg
    )  # and the whole config
    obs = template.obs  # 64 observations of fresh episodes
    q = np.asarray(jax.jit(trainer.net.apply)(saved["best_params"], obs))
    np.testing.assert_allclose(pol.q_values(np.asarray(obs)), q, rtol=1e-5, atol=1e-5)


def test_run_training_refuses_to_overwrite_or_mix_runs(driver_runs, tmp_path):
    cfg = driver_runs["cfg"]
    run = tmp_path / "run"
    shutil.copytree(driver_runs["part"], run)
    before = {p.name: p.read_bytes() for p in run.iterdir()}
    with pytest.raises(ConfigError, match="already holds a run.*--resume"):
        driver.run_training(cfg, run, seed=SEED, progress=False)
    with pytest.raises(ConfigError, match="config differs"):
        driver.run_training(tiny_config(lr=5e-4), run, seed=SEED, resume=True, progress=False)
    with pytest.raises(ConfigError, match="--seed 3"):
        driver.run_training(cfg, run, seed=SEED + 1, resume=True, progress=False)
    with pytest.raises(ConfigError, match="no checkpoint to resume from"):
        driver.run_training(cfg, tmp_path / "empty", seed=SEED, resume=True, progress=False)
    # Nothing was touched.
    assert {p.name: p.read_bytes() for p in run.iterdir()} == before
    # A run made on another number of devices (different random streams) is not resumed here.
    from flax import serialization

    from jaxexo.storage.checkpoint import pack_checkpoint, unpack_checkpoint

    raw = serialization.msgpack_restore(
        unpack_checkpoint((run / run_dir.CHECKPOINT).read_bytes(), "ckpt")
    )
    raw["book"]["devices"] = 2
    (run / run_dir.CHECKPOINT).write_bytes(pack_checkpoint(serialization.msgpack_serialize(raw)))
    with pytest.raises(ConfigError, match="2 device"):
        driver.run_training(cfg, run, seed=SEED, resume=True, progress=False)
