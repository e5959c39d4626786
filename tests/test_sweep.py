"""Sweeps (jaxexo.sweep, ``jaxexo sweep``): sweep files, expansion and grouping, chunk plans, the compiled
vmapped chunk program against solo ``make_train`` runs, divergence, resume, the report, the CLI and
the Ray backend.

Compile time dominates (a chunk program, training plus greedy evaluation, takes 10-20 s to compile),
so one tiny sweep is compiled three times in all:
- in this process on one CPU device (the chunk program, and ``make_train`` alone for the solo runs);
- by ``jaxexo sweep`` (two CPU devices) in a niced subprocess started with the module, which runs on
  the core this process leaves idle; it writes its program to a persistent compilation cache that the
  Ray worker started later reads (the same program on the same inputs: the same results).
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest

from jaxexo.config import HYPER_FIELDS, ConfigError, static_settings
from jaxexo.config.toml_io import config_to_toml
from jaxexo.sweep import plan as P
from jaxexo.sweep import results as R
from jaxexo.sweep.spec import load_sweep, parse_bytes, sweep_from_dict

from conftest import (
    FORWARD_N,
    FORWARD_T,
    FORWARD_UPDATES,
    ROOT,
    cli_cmd,
    forward_raw,
    run_cli,
    run_python,
)

# --------------------------------------------------------------------------------------------
# The tiny sweep: 4 learning rates (one of them absurd: it diverges) x 2 seeds, 6 updates each.
# --------------------------------------------------------------------------------------------

N, T, UPDATES = FORWARD_N, FORWARD_T, FORWARD_UPDATES
HUGE_LR = 1e30
LRS = [1e-3, HUGE_LR, 3e-3, 1e-2]


def tiny_raw(**sweep) -> dict:
    return forward_raw(
        sweep={"seeds": 2, "chunk_size": 4, "grid": {"train.lr": list(LRS)}, **sweep}
    )


def tiny_toml(path) -> None:
    """The tiny sweep as a file (what the CLI and Ray runs read)."""
    raw = tiny_raw()
    cfg = sweep_from_dict(raw).members[0].config
    text = (
        config_to_toml(cfg) + "\n[sweep]\nseeds = 2\nchunk_size = 4\n\n[sweep.grid]\n"
        f'"train.lr" = [{", ".join(repr(x) for x in LRS)}]\n'
    )
    path.write_text(text)


# --------------------------------------------------------------------------------------------
# Sweep files (NumPy only)
# --------------------------------------------------------------------------------------------


def test_grid_expands_in_order_with_every_seed():
    raw = tiny_raw(seeds=[3, 7], grid={"train.lr": [1e-3, 3e-3], "train.lam": [0.5, 0.8, 0.9]})
    sw = sweep_from_dict(raw)
    assert [a.path for a in sw.axes] == ["train.lr", "train.lam"]
    assert len(sw.members) == 6 and sw.seeds == (3, 7) and sw.num_agents == 12
    got = [(m.config.train.lr, m.config.train.lam) for m in sw.members]
    assert got == [(lr, lam) for lr in (1e-3, 3e-3) for lam in (0.5, 0.8, 0.9)]
    assert sw.members[4].values == {"train.lr": 3e-3, "train.lam": 0.8}
    assert sw.members[4].label == "train.lr=0.003, train.lam=0.8"
    # Everything else is the base config.
    assert all(
        m.config.train.num_envs == N and m.config.env.obs_mode == "thesis" for m in sw.members
    )
    assert len(sw.groups) == 1
    assert sw.groups[0].agents == tuple((c, s) for c in range(6) for s in (3, 7))


def test_random_axes_are_seeded_and_respect_their_ranges():
    random = {
        "train.gamma": {"low": 0.9, "high": 0.99},
        "train.target_tau": {"low": 1e-3, "high": 1e-1, "log": True},
        "train.target_period": {"low": 2, "high": 5},
        "layout.pivot": {"choices": ["agent", "obstacle"]},
    }
    raw = tiny_raw(grid={"train.lr": [1e-3, 3e-3]}, random=random, samples=20, sample_seed=4)
    sw = sweep_from_dict(raw)
    assert len(sw.members) == 40
    assert [m.values for m in sweep_from_dict(raw).members] == [
        m.values for m in sw.members
    ]  # reproducible
    other = sweep_from_dict({**raw, "sweep": {**raw["sweep"], "sample_seed": 5}})
    assert [m.values for m in other.members] != [m.values for m in sw.members]
    vals = lambda k: np.array([m.values[k] for m in sw.members], dtype=object)  # noqa: E731
    g, tau, period = (
        vals("train.gamma").astype(float),
        vals("train.target_tau").astype(float),
        vals("train.target_period"),
    )
    assert g.min() >= 0.9 and g.max() <= 0.99 and len(set(g)) == 40
    assert tau.min() >= 1e-3 and tau.max() <= 1e-1
    # log-uniform: about half the draws below the geometric middle 1e-2 (uniform would give ~9 %)
    assert 10 <= (tau < 1e-2).sum() <= 30
    assert (
        all(isinstance(p, int) for p in period)
        and set(period) <= {2, 3, 4, 5}
        and len(set(period)) >= 3
    )
    assert set(vals("layout.pivot")) == {"agent", "obstacle"}
    pivots = {m.values["layout.pivot"]: m.config.layout.pivot for m in sw.members}
    assert pivots == {"agent": (1.0, 0.0, 0.0), "obstacle": (0.0, 1.0, 0.0)}
    # Both grid values appear with 20 draws each, in grid order.
    assert [m.values["train.lr"] for m in sw.members] == [1e-3] * 20 + [3e-3] * 20


def test_vector_element_axes():
    raw = tiny_raw(grid={"reward.traj_weights[3]": [2.0, 8.0], "reward.traj_weights[1]": [0.5]})
    sw = sweep_from_dict(raw)
    w = [m.config.reward.traj_weights for m in sw.members]
    assert w == [(1.0, 0.5, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0), (1.0, 0.5, 1.0, 8.0, 1.0, 1.0, 1.0, 1.0)]
    assert len(sw.groups) == 1  # reward weights are leaves: one program


def test_groups_follow_static_settings():
    # num_envs and the layer sizes change shapes; a budget that needs more updates changes the scan
    # length; a budget within the same number of updates, the learning rate and reward values do not.
    raw = tiny_raw(grid={"train.num_envs": [16, 32], "train.lr": [1e-3, 3e-3]})
    sw = sweep_from_dict(raw)
    assert [g.config_ids for g in sw.groups] == [(0, 1), (2, 3)]
    sw = sweep_from_dict(
        tiny_raw(grid={"train.hidden": [[16], [8, 8]], "reward.goal_reward": [5.0, 10.0]})
    )
    assert [g.config_ids for g in sw.groups] == [(0, 1), (2, 3)]
    steps = N * T * UPDATES
    sw = sweep_from_dict(tiny_raw(grid={"train.budget_env_steps": [steps, steps - 10, 2 * steps]}))
    assert [g.config_ids for g in sw.groups] == [(0, 1), (2,)]
    assert static_settings(sw.members[0].config) == static_settings(sw.members[1].config)
    sw = sweep_from_dict(tiny_raw(grid={"train.trace": ["forward", "backward"]}))
    assert len(sw.groups) == 2
    # Layout distributions of the same size are leaves, a different number of obstacle kinds is not.
    sw = sweep_from_dict(
        tiny_raw(
            grid={
                "layout.pivot": ["agent", "between"],
                "layout.obstacles": [["base1"], ["base2"], ["base1", "base2"]],
            }
        )
    )
    assert [g.config_ids for g in sw.groups] == [(0, 1, 3, 4), (2, 5)]


def test_hyper_fields_are_the_hyperparams_leaves():
    jax = pytest.importorskip("jax")  # noqa: F841
    import dataclasses

    from jaxexo.train.trainer import Hyperparams

    # ...and budget_updates, the env-step budget in whole updates (integer budgets).
    assert tuple(
        f.name for f in dataclasses.fields(Hyperparams) if f.name != "env"
    ) == HYPER_FIELDS + ("budget_updates",)


BAD = [
    ({"grid": {"trian.lr": [1e-3]}}, "sweep.grid.trian.lr", "no config section 'trian'"),
    ({"grid": {"train.learning_rate": [1e-3]}}, "sweep.grid.train.learning_rate", "unknown axis"),
    ({"grid": {"train.lr": []}}, "sweep.grid.train.lr", "empty grid"),
    ({"grid": {"train.lr": 1e-3}}, "sweep.grid.train.lr", "list of values"),
    ({"grid": {"lr": [1e-3]}}, "sweep.grid.lr", "section.field"),
    ({"grid": {"train.lam": [0.5, 1.5]}}, "sweep.grid.train.lam", "train.lam: a fraction"),
    ({"grid": {"train.lr": [-1.0]}}, "sweep.grid.train.lr", "train.lr: must be > 0"),
    (
        {"grid": {}, "random": {"train.gamma": {"low": 0.99, "high": 0.9}}, "samples": 2},
        "sweep.random.train.gamma",
        "bad range",
    ),
    (
        {"grid": {}, "random": {"train.gamma": {"low": 0.9, "high": 0.9}}, "samples": 2},
        "sweep.random.train.gamma",
        "bad range",
    ),
    (
        {"grid": {}, "random": {"train.lr": {"low": 0.0, "high": 1e-2, "log": True}}, "samples": 2},
        "sweep.random.train.lr.low",
        "log range",
    ),
    (
        {"grid": {}, "random": {"train.lr": {"low": 1e-4}}, "samples": 2},
        "sweep.random.train.lr.high",
        "required",
    ),
    (
        {
            "grid": {},
            "random": {"train.lr": {"low": 1e-4, "high": 1e-3, "scale": "log"}},
            "samples": 2,
        },
        "sweep.random.train.lr.scale",
        "unknown field",
    ),
    (
        {"grid": {}, "random": {"train.lr": {"low": "a", "high": 1e-3}}, "samples": 2},
        "sweep.random.train.lr.low",
        "finite number",
    ),
    (
        {"grid": {}, "random": {"train.target_period": {"low": 1.5, "high": 4}}, "samples": 2},
        "sweep.random.train.target_period",
        "integer",
    ),
    (
        {"grid": {}, "random": {"train.lr": {"choices": []}}, "samples": 2},
        "sweep.random.train.lr.choices",
        "non-empty",
    ),
    (
        {"grid": {}, "random": {"train.gamma": {"low": 0.9, "high": 0.99}}},
        "sweep.samples",
        "required",
    ),
    ({"samples": 3}, "sweep.samples", "only meaningful"),
    (
        {
            "grid": {"train.lr": [1e-3]},
            "random": {"train.lr": {"low": 1e-4, "high": 1e-3}},
            "samples": 2,
        },
        "sweep.random.train.lr",
        "already a grid axis",
    ),
    ({"grid": {}}, "sweep.grid", "no axes"),
    ({"seeds": 0}, "sweep.seeds", ">= 1"),
    ({"seeds": [1, 1]}, "sweep.seeds", "repeat"),
    ({"seeds": []}, "sweep.seeds", "non-empty"),
    ({"seed": 3}, "sweep.seed", "unknown field"),
    (
        {"grid": {"reward.traj_weights[8]": [1.0]}},
        r"sweep.grid.reward.traj_weights\[8\]",
        "out of range",
    ),
    ({"grid": {"train.lr[0]": [1.0]}}, r"sweep.grid.train.lr\[0\]", "not a vector"),
    ({"heatmap": ["train.lr", "train.lam"]}, "sweep.heatmap", "not an axis"),
    ({"memory_budget": "4 parsecs"}, "sweep.memory_budget", "unknown unit"),
    ({"chunk_size": 0}, "sweep.chunk_size", ">= 1"),
]


@pytest.mark.parametrize("sweep, field, text", BAD, ids=[f"{i}-{b[1]}" for i, b in enumerate(BAD)])
def test_sweep_errors_name_the_field(sweep, field, text):
    raw = tiny_raw()
    raw["sweep"].update(sweep)
    with pytest.raises(ConfigError, match=field) as info:
        sweep_from_dict(raw)
    assert text in str(info.value), str(info.value)


def test_sweep_file_errors_name_the_file_and_field(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('[sweep]\nbase = "missing.toml"\n[sweep.grid]\n"train.lr" = [1e-3]\n')
    with pytest.raises(
        ConfigError, match=r"s.toml: sweep.base: .*missing.toml: cannot read config"
    ):
        load_sweep(p)
    p.write_text("[train]\nlr = 1e-3\n")
    with pytest.raises(ConfigError, match=r"s.toml: sweep: missing \[sweep\]"):
        load_sweep(p)
    p.write_text('[sweep]\nseeds = 2\n[sweep.grid]\n"train.gamma" = [0.9, 2.0]\n')
    with pytest.raises(
        ConfigError, match=r"s.toml: sweep.grid.train.gamma: configuration 1 .*train.gamma"
    ):
        load_sweep(p)
    with pytest.raises(ConfigError, match="cannot read"):
        load_sweep(tmp_path / "nope.toml")


def test_base_config_is_merged_under_the_sweep_file(tmp_path):
    (tmp_path / "base.toml").write_text(
        '[train]\nnum_envs = 64\nlr = 0.5\nhidden = [8]\n[env]\nobs_mode = "thesis"\n'
    )
    (tmp_path / "s.toml").write_text(
        '[sweep]\nbase = "base.toml"\n[sweep.grid]\n"train.lam" = [0.1, 0.2]\n'
        "[train]\nhidden = [4, 4]\n"
    )
    sw = load_sweep(tmp_path / "s.toml")
    cfg = sw.members[1].config
    assert (cfg.train.num_envs, cfg.train.lr, cfg.train.hidden, cfg.train.lam) == (
        64,
        0.5,
        (4, 4),
        0.2,
    )
    assert cfg.env.obs_mode == "thesis" and not hasattr(
        cfg, "extra"
    )  # [sweep] never reaches the Config
    # The self-contained form rebuilds the same sweep (what a Ray worker receives).
    again = sweep_from_dict(sw.to_dict())
    assert [m.config for m in again.members] == [m.config for m in sw.members]
    assert again.fingerprint() == sw.fingerprint()


def test_fingerprint_covers_results_not_report_options():
    a = sweep_from_dict(tiny_raw())
    assert (
        a.fingerprint()
        == sweep_from_dict(tiny_raw(top=2, chunk_size=2, memory_budget="1GiB")).fingerprint()
    )
    assert a.fingerprint() != sweep_from_dict(tiny_raw(seeds=3)).fingerprint()
    assert a.fingerprint() != sweep_from_dict(tiny_raw(grid={"train.lr": LRS[:3]})).fingerprint()
    raw = tiny_raw()
    raw["train"]["gamma"] = 0.9
    assert a.fingerprint() != sweep_from_dict(raw).fingerprint()


@pytest.mark.parametrize(
    "text, n",
    [
        ("512MiB", 512 * 2**20),
        ("4 GiB", 4 * 2**30),
        ("2GB", 2 * 10**9),
        (1000, 1000),
        ("1.5KiB", 1536),
    ],
)
def test_parse_bytes(text, n):
    assert parse_bytes(text) == n


def test_sweep_files_load_without_jax():
    code = (
        "import sys\nfrom jaxexo.sweep.spec import load_sweep\nfrom jaxexo.sweep.plan import make_plan\n"
        "import jaxexo.sweep.results\n"
        "s = load_sweep('configs/sweeps/smoke.toml')\nmake_plan(s, 2, 2**30)\n"
        "print('JAX' if any(m == 'jax' or m.startswith(('jax.', 'flax')) for m in sys.modules) else 'NOJAX')\n"
    )
    r = run_python(code, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "NOJAX"


def test_bundled_sweeps_load():
    sweeps = {p.stem: load_sweep(p) for p in sorted((ROOT / "configs" / "sweeps").glob("*.toml"))}
    assert {"smoke", "lr_lambda", "reward_weights", "thesis_episodes_pivot"} <= set(sweeps)
    smoke = sweeps["smoke"]
    assert len(smoke.members) == 8 and len(smoke.seeds) == 2 and len(smoke.groups) == 1
    thesis = sweeps["thesis_episodes_pivot"]
    assert {a.path for a in thesis.axes} == {"train.budget_episodes", "layout.pivot"}
    assert len(thesis.groups) == 3  # one compiled program per episode budget
    assert all(m.config.env.obs_mode == "thesis" for m in thesis.members)


def test_ranking_by_mean_success_then_divergence():
    from jaxexo.sweep.report import rank

    sw = sweep_from_dict(tiny_raw())

    def row(cid, seed, success, diverged=0, ret=0.0, reach="nan"):
        return {
            "config_id": str(cid),
            "seed": str(seed),
            "success": repr(success),
            "held_out_success": "0.0",
            "accuracy": "1.0",
            "train_return": repr(ret),
            "episodes_to_90": reach,
            "diverged": str(diverged),
        }

    rows = [
        row(0, 0, 0.5),
        row(0, 1, 0.7, reach="1000.0"),
        row(1, 0, 0.0, 1, ret=9.0),
        row(1, 1, 0.0, 1, ret=9.0),
        row(2, 0, 0.0, ret=-5.0),
        row(2, 1, 0.0, ret=-5.0),
        row(3, 0, 0.9),
        row(3, 1, 0.1, reach="3000.0"),
    ]
    entries = rank(sw, rows)
    assert [e["config_id"] for e in entries] == [
        0,
        3,
        2,
        1,
    ]  # 0.6 > 0.5 (wider spread); 0.0 healthy > diverged
    e0, e3 = entries[0], entries[1]
    assert e0["success_mean"] == pytest.approx(0.6) and e0["success_std"] == pytest.approx(0.1)
    assert (e0["success_min"], e0["success_max"]) == (0.5, 0.7)
    assert (
        e0["episodes_to_90"] == 1000.0
        and e0["reached_90"] == 1
        and e3["success_std"] == pytest.approx(0.4)
    )
    assert entries[3]["diverged"] == 2 and entries[2]["reached_90"] == 0


# --------------------------------------------------------------------------------------------
# Chunk plans (NumPy only)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "agents, devices, cap",
    [(12, 2, 5), (7, 2, 100), (64, 4, 16), (1, 2, 8), (9, 1, 4), (256, 2, 30), (100, 2, 24)],
)
def test_chunk_sizes_are_multiples_of_the_devices_and_pad_least(agents, devices, cap):
    size = P.group_chunk_size(agents, 1, 1, devices, budget=cap)
    assert size % devices == 0 and size <= max(cap, devices)
    chunks = -(-agents // size)
    assert size * (chunks - 1) < agents  # no empty chunk
    top = max(devices, min(cap, agents) // devices * devices)
    waste = lambda s: -(-agents // s) * s - agents  # noqa: E731
    assert all(waste(size) <= waste(s) for s in range(max(devices, top // 2), top + 1, devices))
    assert size >= top // 2


def test_plan_covers_every_agent_once_in_order():
    raw = tiny_raw(grid={"train.num_envs": [16, 32], "train.lr": [1e-3, 3e-3, 1e-2]}, seeds=3)
    raw["sweep"].pop("chunk_size")
    sw = sweep_from_dict(raw)
    per = P.agent_bytes(sw.members[0].config)
    chunks = P.make_plan(sw, devices=2, budget=4 * per)
    assert [c.chunk_id for c in chunks] == list(range(len(chunks)))
    assert [a for c in chunks for a in c.agents] == [a for g in sw.groups for a in g.agents]
    for g in sw.groups:
        sizes = {c.size for c in chunks if c.group_id == g.group_id}
        assert len(sizes) == 1 and sizes.pop() % 2 == 0
    assert all(
        len(c.agents) <= c.size
        and c.size * P.agent_bytes(sw.members[c.agents[0][0]].config) <= 4 * per
        for c in chunks
    )
    with pytest.raises(ConfigError, match="memory_budget: 2 agent"):
        P.make_plan(sw, devices=2, budget=per)
    # The chunk program's own estimate grows with the batch.
    big = sweep_from_dict(tiny_raw(grid={"train.num_envs": [4096]})).members[0].config
    assert P.agent_bytes(big) > 100 * per / 2


# --------------------------------------------------------------------------------------------
# Compiled runs: module fixtures
# --------------------------------------------------------------------------------------------

jax = pytest.importorskip("jax")


def _subprocess_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    # RAY_AUTH_MODE: the test cluster listens on loopback only; without it Ray turns token
    # authentication on whenever ~/.ray/auth_token exists, a file other Ray runs on this machine
    # create and replace (a cluster and its client could then hold different tokens).
    env.update(
        RAY_USAGE_STATS_ENABLED="0",
        RAY_AUTH_MODE="disabled",
    )
    return env


@pytest.fixture(scope="module")
def cli_local(tmp_path_factory):
    """``jaxexo sweep tiny.toml --out DIR --export-best --export-all --quiet`` (every CPU core as a device), niced,
    in the background from the first test that needs it."""
    tmp = tmp_path_factory.mktemp("cli")
    tiny_toml(tmp / "tiny.toml")
    proc = subprocess.Popen(
        cli_cmd(
            "sweep",
            tmp / "tiny.toml",
            "--out",
            tmp / "out",
            "--export-best",
            "--export-all",
            "--quiet",
        ),
        cwd=ROOT,
        env=_subprocess_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        os.setpriority(os.PRIO_PROCESS, proc.pid, 10)
    except (AttributeError, OSError):
        pass
    state = {"proc": proc, "dir": tmp, "out": tmp / "out", "result": None}

    def wait():
        if state["result"] is None:
            state["result"] = proc.communicate(timeout=600)
        assert proc.returncode == 0, state["result"][1][-3000:]
        return state["result"]

    state["wait"] = wait
    yield state
    if proc.poll() is None:
        proc.kill()
        proc.communicate()


@pytest.fixture(scope="module")
def tiny_sweep():
    return sweep_from_dict(tiny_raw())


@pytest.fixture(scope="module")
def inproc(cli_local, tiny_sweep, tmp_path_factory):
    """The tiny sweep run here on one CPU device, straight through (after the CLI run started)."""
    from jaxexo.sweep.runner import run_sweep

    out = tmp_path_factory.mktemp("inproc") / "full"
    summary = run_sweep(tiny_sweep, out, progress=False, devices=jax.local_devices()[:1])
    return {"out": out, "summary": summary}


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def _without_wall(rows):
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows]


# --------------------------------------------------------------------------------------------
# Compiled runs: the vmapped program against solo runs, divergence
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_agents_match_solo_make_train_runs_and_divergence_is_contained(inproc, tiny_sweep):
    """Every agent of the chunk program (vmapped with its neighbours, evaluation fused in) ends where
    ``make_train`` alone ends for its config and seed, up to float reassociation in batched matrix
    products; the huge learning rate diverges, is flagged, and its chunk neighbours are unharmed."""
    from jaxexo.sweep.program import unflatten
    from jaxexo.train.trainer import Hyperparams, Trainer, make_train

    out = inproc["out"]
    rows = {(int(r["config_id"]), int(r["seed"])): r for r in _rows(out / R.RESULTS)}
    assert len(rows) == 8
    plan = json.loads((out / R.PLAN).read_text())
    # The diverging configuration (1) shares chunk 0, one vmapped batch, with configuration 0.
    assert [c["agents"] for c in plan["chunks"]] == [
        [[0, 0], [0, 1], [1, 0], [1, 1]],
        [[2, 0], [2, 1], [3, 0], [3, 1]],
    ]
    cfg0 = tiny_sweep.members[0].config
    solo = jax.jit(make_train(cfg0))  # one program for every lr: they are leaves
    init = jax.jit(Trainer(cfg0).init)
    for chunk in plan["chunks"]:
        data = R.load_chunk(out, chunk["chunk_id"])
        for i, (cid, seed) in enumerate(data["agents"]):
            cfg = tiny_sweep.members[cid].config
            hyper = Hyperparams.from_config(cfg)
            row = rows[(cid, seed)]
            assert float(row["train.lr"]) == LRS[cid] and int(row["env_steps"]) == N * T * UPDATES
            ts, m = solo(jax.random.PRNGKey(seed), hyper)
            if LRS[cid] == HUGE_LR:
                assert row["diverged"] == "1"
                assert not all(
                    np.all(np.isfinite(x)) for x in jax.tree.leaves(m)
                )  # the solo run diverges too
                continue
            assert row["diverged"] == "0"
            assert int(row["episodes"]) == int(ts.episodes)
            got = jax.tree.leaves(unflatten(data["params"], i))
            want = jax.tree.leaves(jax.tree.map(np.asarray, ts.params))
            start = jax.tree.leaves(
                jax.tree.map(np.asarray, init(jax.random.PRNGKey(seed), hyper).params)
            )
            assert len(got) == len(want) == 4
            for g, w, s0 in zip(got, want, start):
                np.testing.assert_allclose(g, w, rtol=1e-4, atol=1e-5)
                assert np.abs(w - s0).max() > 1e-3  # trained: the comparison has teeth
    for cid, seed in [(0, 0), (0, 1), (2, 0), (3, 1)]:
        r = rows[(cid, seed)]
        assert all(np.isfinite(float(r[k])) for k in ("success", "accuracy", "eval_return"))
        assert 0.0 <= float(r["success"]) <= float(r["accuracy"]) <= 1.0
    summary = (out / "summary.md").read_text()
    assert "Diverged" in summary and f"train.lr={HUGE_LR:.4g}" in summary


@pytest.mark.slow
def test_memory_estimate_covers_the_compiled_program(inproc, tiny_sweep):
    """agent_bytes x chunk size is at least what XLA allocates for the chunk program (arguments,
    outputs and temporaries), and not absurdly more."""
    from jaxexo.sweep.plan import Chunk
    from jaxexo.sweep.program import chunk_inputs, chunk_program

    plan = json.loads((inproc["out"] / R.PLAN).read_text())
    chunk = Chunk.from_json(plan["chunks"][0])
    cfg = tiny_sweep.members[0].config
    program = chunk_program(cfg, jax.local_devices()[:1])
    stats = program.lower(*chunk_inputs(tiny_sweep, chunk)).compile().memory_analysis()
    used = stats.argument_size_in_bytes + stats.output_size_in_bytes + stats.temp_size_in_bytes
    estimate = P.agent_bytes(cfg) * chunk.size
    assert used <= estimate <= 50 * used, (used, estimate)


# --------------------------------------------------------------------------------------------
# Resume
# --------------------------------------------------------------------------------------------


class _StopAfter:
    """Patches results.append_rows to raise KeyboardInterrupt on its ``at``-th call (one call per
    finished chunk, after its chunk file was saved)."""

    def __init__(self, at: int):
        self.at, self.calls, self.real = at, 0, R.append_rows

    def __call__(self, *args):
        self.calls += 1
        if self.calls == self.at:
            raise KeyboardInterrupt
        return self.real(*args)


@pytest.mark.slow
def test_resume_skips_finished_chunks_and_ends_identical(inproc, tiny_sweep, tmp_path):
    from jaxexo.sweep import program, runner

    out = tmp_path / "part"
    dev = jax.local_devices()[:1]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(R, "append_rows", _StopAfter(2))
        with pytest.raises(KeyboardInterrupt):
            runner.run_sweep(tiny_sweep, out, progress=False, devices=dev)
    # Chunk 0 finished (rows and file), chunk 1's file was saved but its rows were not written; a
    # torn half row at the end (a write cut short) is dropped on resume.
    assert len(_rows(out / R.RESULTS)) == 4 and R.chunk_path(out, 1).exists()
    with (out / R.RESULTS).open("a") as f:
        f.write("2,0,0,1,half a ro")
    ran = []
    real = program.run_chunk

    def spy(sweep, chunk, devices=None):
        ran.append(chunk.chunk_id)
        return real(sweep, chunk, devices)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(program, "run_chunk", spy)
        with pytest.raises(ConfigError, match="already holds a sweep"):
            runner.run_sweep(tiny_sweep, out, progress=False, devices=dev)
        runner.run_sweep(tiny_sweep, out, resume=True, progress=False, devices=dev)
        assert ran == [1]
        # Resuming a finished sweep runs nothing and rewrites the same report.
        runner.run_sweep(tiny_sweep, out, resume=True, progress=False, devices=dev)
        assert ran == [1]
    full = inproc["out"]
    assert _without_wall(_rows(out / R.RESULTS)) == _without_wall(_rows(full / R.RESULTS))
    for c in (0, 1):
        a, b = R.load_chunk(out, c), R.load_chunk(full, c)
        assert a["agents"] == b["agents"] and np.array_equal(
            a["curves"], b["curves"], equal_nan=True
        )
        assert all(
            np.array_equal(a["params"][k], b["params"][k], equal_nan=True) for k in a["params"]
        )
    # Another sweep in the same folder is refused.
    other = sweep_from_dict(tiny_raw(seeds=3))
    with pytest.raises(ConfigError, match="sweep differs"):
        runner.run_sweep(other, out, resume=True, progress=False, devices=dev)
    with pytest.raises(ConfigError, match="no sweep to resume"):
        runner.run_sweep(tiny_sweep, tmp_path / "empty", resume=True, progress=False, devices=dev)
    with pytest.raises(ConfigError, match="--heatmap: expected two different axes"):
        runner.run_sweep(
            tiny_sweep,
            tmp_path / "h",
            heatmap=("train.lr", "train.gamma"),
            progress=False,
            devices=dev,
        )
    assert not (tmp_path / "h").exists()


# --------------------------------------------------------------------------------------------
# The CLI and the report
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_cli_sweep_writes_results_report_and_best_policy(cli_local, tiny_sweep):
    from jaxexo.config import load_config
    from jaxexo.storage.policy_file import load_policy

    stdout, stderr = cli_local["wait"]()
    out = cli_local["out"]
    rows = _rows(out / R.RESULTS)
    assert [(int(r["config_id"]), int(r["seed"])) for r in rows] == [
        (c, s) for c in range(4) for s in (0, 1)
    ]
    cols = list(rows[0])
    for c in [
        "config_id",
        "seed",
        "label",
        "train.lr",
        *(f"train.{f}" for f in HYPER_FIELDS),
        "reward.goal_reward",
        "reward.traj_weights",
        *R.SCALARS,
        "wall_s",
    ]:
        assert c in cols, c
    assert json.loads(rows[0]["reward.traj_weights"]) == [1.0] * 8
    assert {r["diverged"] for r in rows} == {"0", "1"}
    assert [r["diverged"] for r in rows if float(r["train.lr"]) == HUGE_LR] == ["1", "1"]
    plan = json.loads((out / R.PLAN).read_text())
    assert plan["devices"] == os.cpu_count() or plan["devices"] >= 1
    summary = (out / "summary.md").read_text()
    table = [ln for ln in summary.splitlines() if ln.startswith("| ") and ln[2].isdigit()]
    assert len(table) == 4
    means = [float(ln.split("|")[4].split("±")[0]) for ln in table]
    assert means == sorted(means, reverse=True)
    for name in ("heatmap.png", "curves.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    sel = json.loads((out / "best" / "selection.json").read_text())
    best_cfg = int(table[0].split("|")[2])
    assert sel["config_id"] == best_cfg and sel["label"] == tiny_sweep.members[best_cfg].label
    assert load_config(out / "best" / "config.toml") == tiny_sweep.members[best_cfg].config
    pol = load_policy(out / "best" / "policy.npz")
    assert pol.metadata["layers"] == [2, 16, 36]
    # The exported parameters are the chosen agent's final ones.
    from jaxexo.sweep.program import unflatten

    row = next(
        r for r in rows if int(r["config_id"]) == sel["config_id"] and int(r["seed"]) == sel["seed"]
    )
    data = R.load_chunk(out, int(row["chunk"]))
    params = unflatten(data["params"], data["agents"].index((sel["config_id"], sel["seed"])))
    np.testing.assert_array_equal(pol.kernels[0], params["params"]["dense_0"]["kernel"])
    assert "8 agents" in stdout.replace("= 8 agents", "8 agents") and "best/policy.npz" in stdout
    assert "\r" not in stderr  # --quiet: no progress bar


@pytest.mark.slow
def test_cli_bad_sweep_exits_2_naming_the_field(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('[sweep]\nseeds = 2\n[sweep.grid]\n"train.lamda" = [0.5]\n')
    r = run_cli("sweep", p, "--out", tmp_path / "out", "--quiet", timeout=120)
    assert r.returncode == 2, r.stderr
    assert "sweep.grid.train.lamda" in r.stderr and "unknown axis" in r.stderr
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------------------------
# Ray
# --------------------------------------------------------------------------------------------


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _RayNode:
    """``ray start --block`` in its own process group (ended as a group at teardown)."""

    def __init__(self, args, env, log):
        ray_bin = os.path.join(os.path.dirname(sys.executable), "ray")
        self.log = open(log, "w")
        self.proc = subprocess.Popen(
            [ray_bin, "start", "--block", "--disable-usage-stats", *args],
            env=env,
            stdout=self.log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )

    def signal(self, sig) -> None:
        try:
            os.killpg(self.proc.pid, sig)
        except ProcessLookupError:
            pass


def _stop_nodes(nodes, grace: float = 5.0) -> None:
    """SIGTERM to every node's process group, SIGKILL to what is left after ``grace`` seconds."""
    for n in nodes:
        n.signal(signal.SIGTERM)
    end = time.monotonic() + grace
    for n in nodes:
        try:
            n.proc.wait(timeout=max(0.1, end - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
        n.signal(signal.SIGKILL)
        n.proc.wait(timeout=10)
        n.log.close()


@pytest.fixture
def ray_cluster():
    """A real Ray cluster on loopback: a head (no CPUs for tasks) and one worker node with two CPUs,
    each a ``ray start --block`` process; both are ended with the test."""
    pytest.importorskip("ray")
    tmp = tempfile.mkdtemp(prefix="jxr", dir="/tmp")  # short: Ray's socket paths must fit 107 bytes
    env = _subprocess_env()
    # A private HOME: a token in the user's ~/.ray/auth_token (Ray's token authentication) must not
    # leak into this loopback cluster, whose nodes and client would then disagree about it.
    env["HOME"] = tmp
    port = _free_port()
    common = ["--node-ip-address=127.0.0.1", "--object-store-memory=100000000"]
    head = _RayNode(
        [
            "--head",
            f"--port={port}",
            "--num-cpus=0",
            "--include-dashboard=false",
            f"--temp-dir={tmp}",
            *common,
        ],
        env,
        os.path.join(tmp, "head.log"),
    )
    nodes = [head]
    try:
        _wait_for_port(port, head, timeout=60)
        nodes.append(
            _RayNode(
                [f"--address=127.0.0.1:{port}", "--num-cpus=2", *common],
                env,
                os.path.join(tmp, "worker.log"),
            )
        )
        yield {"address": f"127.0.0.1:{port}", "env": env}
    finally:
        _stop_nodes(nodes)
        shutil.rmtree(tmp, ignore_errors=True)


def _wait_for_port(port, node, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if node.proc.poll() is not None:
            raise RuntimeError(f"ray head exited early (see {node.log.name})")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise TimeoutError("the Ray head did not open its port")


@pytest.mark.slow
def test_ray_backend_gives_the_local_results(ray_cluster, cli_local, tmp_path):
    """The tiny sweep through a Ray cluster (head + worker processes on 127.0.0.1): each chunk a task
    on the worker with two CPUs exposed as JAX devices, as the local run had: identical results."""
    cli_local["wait"]()
    out = tmp_path / "ray"
    r = subprocess.run(
        cli_cmd(
            "sweep",
            cli_local["dir"] / "tiny.toml",
            "--out",
            out,
            "--backend",
            "ray",
            "--address",
            ray_cluster["address"],
            "--task-cpus",
            "2",
            "--quiet",
        ),
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=ray_cluster["env"],
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    local = cli_local["out"]
    local_plan = json.loads((local / R.PLAN).read_text())
    ray_plan = json.loads((out / R.PLAN).read_text())
    if local_plan["devices"] != 2:
        pytest.skip("the local run did not have two CPU devices to compare with")
    assert ray_plan["chunks"] == local_plan["chunks"]
    assert _without_wall(_rows(out / R.RESULTS)) == _without_wall(_rows(local / R.RESULTS))
    for c in range(len(ray_plan["chunks"])):
        a, b = R.load_chunk(out, c), R.load_chunk(local, c)
        assert all(
            np.array_equal(a["params"][k], b["params"][k], equal_nan=True) for k in a["params"]
        )


@pytest.mark.slow
def test_export_all_writes_each_agent_and_skips_the_diverged(cli_local, tiny_sweep):
    """``--export-all``: every agent that did not diverge gets its own final parameters and resolved
    config (checked against the chunk file and the sweep's member); the diverged are indexed, not
    exported."""
    from jaxexo.config import load_config
    from jaxexo.storage.policy_file import load_policy
    from jaxexo.sweep.program import unflatten
    from jaxexo.sweep.report import agent_dir

    cli_local["wait"]()
    out = cli_local["out"]
    rows = _rows(out / R.RESULTS)
    index = json.loads((out / "agents" / "index.json").read_text())
    diverged = {(int(r["config_id"]), int(r["seed"])) for r in rows if r["diverged"] == "1"}
    assert diverged and sum(e["exported"] for e in index) == 8 - len(diverged)
    assert [(e["config_id"], e["seed"]) for e in index] == [
        (c, s) for c in range(4) for s in (0, 1)
    ]
    for e, r in zip(index, sorted(rows, key=lambda r: (int(r["config_id"]), int(r["seed"])))):
        key = (e["config_id"], e["seed"])
        d = agent_dir(out, *key)
        assert e["exported"] == (key not in diverged) == (d / "policy.npz").exists()
        if not e["exported"]:
            continue
        data = R.load_chunk(out, int(r["chunk"]))
        params = unflatten(data["params"], data["agents"].index(key))
        np.testing.assert_array_equal(
            load_policy(d / "policy.npz").kernels[0], params["params"]["dense_0"]["kernel"]
        )
        assert load_config(d / "config.toml") == tiny_sweep.members[key[0]].config
