"""Populations: a member's result does not depend on who shares its program, the driver
exports the best member's best chunk and records every member, bad values are refused.

One tiny forward-view config (16 environments, 6 updates in 3 chunks of 2); the programs are shared
through the module's compilation cache (a population of 1 and of 2 are the same padded program)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict

from conftest import FORWARD_UPDATES, forward_raw, metrics_without_clock
from train_helpers import leaves, metric_array

jax = pytest.importorskip("jax")

from jaxexo.sweep.program import run_chunk, unflatten  # noqa: E402
from jaxexo.sweep.spec import sweep_from_dict  # noqa: E402
from jaxexo.train import checkpoints, driver, run_dir  # noqa: E402
from jaxexo.train.lanes import LANES, padded_agents  # noqa: E402
from jaxexo.train.network import dense_layers  # noqa: E402
from jaxexo.train.population import Population, population_devices  # noqa: E402
from jaxexo.train.records import Track  # noqa: E402
from jaxexo.train.trainer import METRICS  # noqa: E402

UPDATES, CHUNK = FORWARD_UPDATES, 2
SEED = 3


def raw(**train) -> dict:
    return forward_raw({"chunk_updates": CHUNK, "lr": 3e-3, **train})


def train_members(seeds):
    """Every chunk of a Population of ``seeds``: per member its metrics rows, validation scores and
    final parameters (host arrays)."""
    pop = Population(config_from_dict(raw()), seeds)
    ts = pop.init()
    metrics, scores, params = [], [], []
    for _ in range(UPDATES // CHUNK):
        ts, m, score, finite = pop.chunk(ts)
        assert np.asarray(finite)[: pop.size].all()
        metrics.append(metric_array(m)[: pop.size])
        scores.append(np.asarray(score)[: pop.size])
        params.append(pop.real(ts.params))
    return [
        {
            "metrics": np.stack([m[i] for m in metrics]),
            "scores": np.array([s[i] for s in scores]),
            "chunk_params": [jax.tree.map(lambda x: x[i], p) for p in params],
            "params": jax.tree.map(lambda x: x[i], params[-1]),
        }
        for i in range(pop.size)
    ]


def same(a, b) -> bool:
    la, lb = leaves(a), leaves(b)
    return len(la) == len(lb) and all(
        x.dtype == y.dtype and np.array_equal(x, y) for x, y in zip(la, lb)
    )


def test_the_devices_check_trains_this_config():
    """benchmarks/population_devices_check.py trains, across device counts, the config of these tests
    (written out in benchmarks/benchlib/population_devices.toml, as a script reads it)."""
    from jaxexo.config import load_config

    from benchlib.population_bench import DEVICES_CHECK
    from benchlib.population_bench import SEED as CHECKED

    assert load_config(DEVICES_CHECK) == config_from_dict(raw()) and CHECKED == SEED


def test_a_member_trains_identically_alone_in_populations_of_2_and_5_and_in_a_sweep_group_of_8():
    alone = train_members([SEED])[0]
    neighbour, pair = train_members([SEED - 1, SEED])  # pair: the second lane of the block
    five = train_members([0, 1, 2, SEED, 4])[SEED]  # second block of three, on one device
    assert alone["metrics"].shape == (UPDATES // CHUNK, CHUNK, len(METRICS))
    assert alone["metrics"][..., METRICS.index("loss")].all()  # it trained: every update had a loss
    for other in (pair, five):
        assert same(alone["params"], other["params"])
        assert np.array_equal(alone["metrics"], other["metrics"])
        assert np.array_equal(alone["scores"], other["scores"])
    # The other members are other agents (the comparison above could not pass by everything being equal).
    assert not same(alone["params"], neighbour["params"])
    # In a sweep chunk of 8 agents (seeds 0..7, the whole budget in one scan): the same final parameters.
    r = raw()
    r["sweep"] = {"seeds": 8, "chunk_size": 8, "grid": {"train.lr": [3e-3]}}
    sweep = sweep_from_dict(r)
    out = run_chunk(sweep, sweep_from_plan(sweep))
    i = [s for _, s in out.agents].index(SEED)
    assert same(unflatten(out.params, i), alone["params"])


def sweep_from_plan(sweep):
    from jaxexo.sweep.plan import make_plan

    (chunk,) = make_plan(sweep, devices=1, budget=2**34)
    assert chunk.size == 8
    return chunk


@pytest.mark.parametrize(
    "members, devices, used, padded",
    [
        (1, 2, 2, 4),
        (1, 1, 1, 2),
        (4, 2, 2, 4),
        (5, 2, 2, 8),
        (8, 8, 4, 8),
        (2, 8, 2, 4),
        (3, 1, 1, 4),
    ],
)
def test_population_layout_is_whole_blocks_of_lanes(members, devices, used, padded):
    assert LANES == 2
    assert len(population_devices(members, list(range(devices)))) == used
    assert padded_agents(members, used) == padded


def test_the_choice_skips_diverged_members_and_prefers_the_lower_seed_on_a_tie():
    assert (
        Track(None, np.array([0.4, 0.8, 0.8]), np.array([2, 3, 1]), np.array([0, 0, 0])).lead() == 1
    )
    assert (
        Track(None, np.array([0.4, 0.9, 0.8]), np.array([2, 3, 1]), np.array([0, 2, 0])).lead() == 2
    )
    assert Track(None, np.array([0.4, 0.9]), np.array([0, 3]), np.array([0, 1])).lead() is None


@pytest.mark.parametrize(
    "value, text", [(0, "> 0"), (-2, "> 0"), (2.5, "integer"), (10**6, "<= 4096")]
)
def test_bad_population_values_name_the_field(value, text):
    with pytest.raises(ConfigError, match=rf"train\.population: .*{text}"):
        config_from_dict(raw(population=value))


def test_a_population_too_large_for_memory_is_refused_naming_the_field():
    from jaxexo.config.memory import check_memory, estimate_memory_bytes

    cfg = config_from_dict(raw(population=64))
    one = estimate_memory_bytes(config_from_dict(raw()))
    check_memory(cfg, available=64 * one)
    with pytest.raises(ConfigError, match=r"train\.population: .*at most 10 members"):
        check_memory(cfg, available=10 * one + 1)


def test_the_driver_exports_the_best_member_records_every_member_and_resumes(tmp_path, monkeypatch):
    # Two members: on one device the same padded program as a member alone (compiled once for the module).
    from jaxexo.train import selection

    monkeypatch.setattr(selection, "SELECTION_SCENES", 24)  # the choice's rule, on fewer scenes
    cfg = config_from_dict(raw(population=2))
    res = driver.run_training(cfg, tmp_path / "run", seed=SEED, progress=False)
    rows = [json.loads(x) for x in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == UPDATES // CHUNK and all(len(r["members"]) == 2 for r in rows)
    assert [m["seed"] for m in rows[0]["members"]] == [SEED, SEED + 1]
    assert res["population"] == 2 and [m["seed"] for m in res["members"]] == [SEED, SEED + 1]
    k = res["exported_member"]
    # Exported: the candidate a wearer would choose (jaxexo.train.selection), every candidate scored and
    # written beside the policy.
    sel = res["selection"]
    assert [r["seed"] for r in sel] == [SEED, SEED + 1]
    key = lambda r: (  # noqa: E731
        -r["safe"],
        math.inf if r["cost"] is None else r["cost"],
        -r["validation_success"],
        r["seed"],
    )
    assert min(range(2), key=lambda i: key(sel[i])) == k
    for i, r in enumerate(sel):
        assert r["validation_success"] == res["members"][i]["validation_success_raw"]
        assert (tmp_path / "run" / "members" / f"seed_{SEED + i}.npz").is_file()
    assert res["validation_success_raw"] == res["members"][k]["validation_success_raw"]
    assert res["seed"] == SEED + k and res["selected_chunk"] == res["members"][k]["selected_chunk"]
    for m in res["members"]:
        assert len(m["validation_curve"]) == UPDATES // CHUNK
        assert m["validation_success_raw"] == max(m["validation_curve"])
        assert m["test"]["success_raw"] is not None
    assert res["success_raw"] == res["members"][k]["test"]["success_raw"]
    # The exported policy is that member's parameters after its selected chunk, as it trains alone.
    alone = train_members([SEED + k])[0]
    assert np.array_equal(
        [r["members"][k]["validation_success_raw"] for r in rows], alone["scores"].astype(float)
    )
    chosen = dense_layers(alone["chunk_params"][res["selected_chunk"] - 1])
    policy = np.load(tmp_path / "run" / "policy.npz")
    assert len(chosen) == 2
    for j, (w, b) in enumerate(chosen):
        assert np.array_equal(policy[f"dense_{j}_kernel"], w) and np.array_equal(
            policy[f"dense_{j}_bias"], b
        )
    # Interrupted after its second checkpoint and resumed: the same files as the uninterrupted run.
    real, calls = checkpoints.checkpoint_write, []

    def killed_after_second_checkpoint(path, data):
        if path.name == run_dir.BOOKKEEPING:
            calls.append(path)
            if len(calls) == 2:
                raise RuntimeError("killed")
        return real(path, data)

    monkeypatch.setattr(checkpoints, "checkpoint_write", killed_after_second_checkpoint)
    with pytest.raises(RuntimeError, match="killed"):
        driver.run_training(cfg, tmp_path / "cut", seed=SEED, progress=False)
    monkeypatch.setattr(checkpoints, "checkpoint_write", real)
    with pytest.raises(ConfigError, match="--seed 3"):
        driver.run_training(cfg, tmp_path / "cut", seed=SEED + 1, resume=True, progress=False)
    resumed = driver.run_training(cfg, tmp_path / "cut", seed=SEED, resume=True, progress=False)
    full = res
    clock = ("train_seconds", "selection_seconds")
    assert {k: v for k, v in resumed.items() if k not in clock} == {
        k: v for k, v in full.items() if k not in clock
    }
    assert (tmp_path / "cut" / "policy.npz").read_bytes() == (
        tmp_path / "run" / "policy.npz"
    ).read_bytes()
    assert metrics_without_clock(tmp_path / "cut" / "metrics.jsonl") == metrics_without_clock(
        tmp_path / "run" / "metrics.jsonl"
    )


def test_a_sweep_refuses_a_population():
    r = raw(population=2)
    r["sweep"] = {"seeds": 2, "grid": {"train.lr": [1e-3]}}
    with pytest.raises(ConfigError, match=r"train\.population: a sweep trains its seeds itself"):
        sweep_from_dict(r)


def test_a_diverged_member_is_dropped_from_the_choice_not_the_run(tmp_path, monkeypatch):
    from jaxexo.train import population

    class OneDiverges(population.Population):
        """The second member's learning rate absurd (a leaf: the same compiled program)."""

        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            lr = np.array(self.hyper.lr, copy=True)
            lr[1] = 1e30
            self.hyper = self.hyper.replace(lr=lr)

    monkeypatch.setattr(population, "Population", OneDiverges)
    res = driver.run_training(
        config_from_dict(raw(population=2)), tmp_path / "run", seed=SEED, progress=False
    )
    rows = [json.loads(x) for x in (tmp_path / "run" / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == UPDATES // CHUNK  # the others trained to the end
    assert [r["members"][1]["diverged"] for r in rows] == [True] * len(rows)
    assert res["members"][1]["diverged_chunk"] == 1 and res["members"][1]["selected_chunk"] == 0
    assert res["members"][1]["validation_curve"] == [None] * len(rows)
    assert res["exported_member"] == 0 and res["members"][0]["diverged_chunk"] is None


@pytest.mark.parametrize(
    "command", [["train", "--out", "{tmp}/run"], ["reproduce", "--out", "{tmp}/repro"]]
)
def test_the_cli_refuses_a_bad_population_before_training(tmp_path, command):
    import subprocess
    import sys

    args = [a.format(tmp=tmp_path) for a in command] + ["--population", "0"]
    out = subprocess.run(
        [sys.executable, "-m", "jaxexo.cli", *args], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 2 and "--population: must be > 0, got 0" in out.stderr
    assert not (tmp_path / "run").exists() and not (tmp_path / "repro").exists()
