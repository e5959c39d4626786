"""Nothing lost, nothing faked: run directories, locks, checksums, divergence, counters.

Each fault is produced for real: a process killed with SIGKILL mid-run, two processes on one
directory, corrupted files, a full disk (a small RLIMIT_FSIZE in a subprocess, SIGXFSZ ignored so the
write raises). Every refusal must exit non-zero, name the file or field, print no traceback, and leave
what was already written intact. docs/reliability.md lists these cases.

The tests that train in subprocesses are marked slow and share one tiny config (tests/train_helpers.py's
pattern) and the session's compilation cache (conftest).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from jaxexo.config import ConfigError
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.checkpoint import CheckpointError, pack_checkpoint, unpack_checkpoint
from jaxexo.storage.policy_file import PolicyFileError, load_policy, policy_checksum
from jaxexo.storage.rundir import LOCK_NAME, RunDirError, run_lock

from conftest import (
    ROOT,
    SEED,
    cli_cmd,
    metrics_without_clock,
    run_cli,
    tiny_config,
    without_compilation_cache,
)


def start_training(cfg_path, run, stdout) -> subprocess.Popen:
    """``jaxexo train`` of ``cfg_path`` into ``run`` (seed SEED, one CPU device) as a background
    process, its standard error piped (text) and its standard output to ``stdout``."""
    return subprocess.Popen(
        cli_cmd("train", cfg_path, "--out", run, "--quiet", "--seed", SEED),
        cwd=ROOT,
        env=one_device_env(),
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
    )


def one_device_env() -> dict:
    env = dict(os.environ)
    env["XLA_FLAGS"] = "--xla_force_host_platform_device_count=1"  # as the in-process runs here
    return env


def assert_clean_refusal(r: subprocess.CompletedProcess, *needles: str, code: int = 2):
    """Non-zero exit, a one-line ``jaxexo: error`` naming what is wrong, and no traceback."""
    assert r.returncode == code, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "jaxexo: error:" in r.stderr, r.stderr[-2000:]
    for n in needles:
        assert n in r.stderr, (n, r.stderr[-2000:])


def snapshot(directory) -> dict:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.name != LOCK_NAME}


# Runs a command whose files may not grow past a limit, a write past it raising (EFBIG) instead of
# killing the process with SIGXFSZ: a full disk as the process sees it. The limit and the ignored signal
# are set in a fresh interpreter that then execs the command (both survive exec), rather than in a
# preexec_fn, which would fork this JAX-threaded process.
_LIMITED = (
    "import os, resource, signal, sys\n"
    "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
    "n = int(sys.argv[1]); resource.setrlimit(resource.RLIMIT_FSIZE, (n, n))\n"
    "os.execv(sys.argv[2], sys.argv[2:])\n"
)


def limited_fsize(limit: int, cmd: list) -> list:
    return [sys.executable, "-c", _LIMITED, str(limit), *map(str, cmd)]


# --------------------------------------------------------------------------------------------
# Atomic writes under a full disk (no JAX)
# --------------------------------------------------------------------------------------------


def test_atomic_write_on_a_full_disk_keeps_the_old_file_and_leaves_no_tmp(tmp_path):
    target = tmp_path / "data.bin"
    target.write_bytes(b"old content\n")
    code = (
        "import sys; from jaxexo.storage.atomic import atomic_write\n"
        "try:\n    atomic_write(sys.argv[1], b'x' * 100000)\n"
        "except OSError as e:\n    print(e); sys.exit(7)\n"
    )
    r = subprocess.run(
        limited_fsize(4096, [sys.executable, "-c", code, target]),
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert r.returncode == 7, r.stderr
    assert (
        "could not write" in r.stdout and str(target) in r.stdout and "File too large" in r.stdout
    )
    assert target.read_bytes() == b"old content\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.bin"]


# --------------------------------------------------------------------------------------------
# The checkpoint envelope (no JAX)
# --------------------------------------------------------------------------------------------


def test_checkpoint_envelope_refuses_corrupt_truncated_random_and_old_files(tmp_path):
    payload = bytes(range(256)) * 40
    good = pack_checkpoint(payload)
    assert unpack_checkpoint(good, "c") == payload
    rng = np.random.default_rng(0)
    flipped = bytearray(good)
    for i in rng.choice(
        np.arange(100, len(good)), 64, replace=False
    ):  # 64 flipped bytes in the payload
        flipped[i] ^= 0xFF
    cases = {
        "flipped": (bytes(flipped), "checksum mismatch"),
        "truncated": (good[: len(good) // 2], "checksum mismatch"),
        "empty": (b"", "not a jaxexo checkpoint"),
        "random": (rng.bytes(5000), "not a jaxexo checkpoint"),
        "old": (payload, "not a jaxexo checkpoint"),  # an older jaxexo: bare msgpack, no header
        "version": (good.replace(b"checkpoint 1 ", b"checkpoint 9 ", 1), "version 9"),
        "header": (b"jaxexo-checkpoint 1 sha256=abc\n" + payload, "damaged checkpoint header"),
    }
    for name, (data, message) in cases.items():
        path = tmp_path / f"{name}.msgpack"
        with pytest.raises(CheckpointError, match=message) as info:
            unpack_checkpoint(data, path)
        assert str(path) in str(info.value), name


# --------------------------------------------------------------------------------------------
# Policy files: every field required, dtypes and finiteness checked, checksum verified (no JAX)
# --------------------------------------------------------------------------------------------


def _layers(obs_dim=5, hidden=(8, 8), actions=36, seed=0):
    rng = np.random.default_rng(seed)
    sizes = [obs_dim, *hidden, actions]
    ks = [rng.normal(size=(a, b)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:])]
    bs = [rng.normal(size=b).astype(np.float32) for b in sizes[1:]]
    ss = [rng.normal(size=h).astype(np.float32) for h in hidden]
    nb = [rng.normal(size=h).astype(np.float32) for h in hidden]
    meta = {
        "obs_mode": "conditioned",
        "obs_dim": obs_dim,
        "num_actions": actions,
        "layers": sizes,
        "layer_norm": True,
        "activation": "relu",
        "length_scale": 1.0,
        "thesis_obs_center": [0.0, 0.0],
        "action_angles_rad": [0.1 * k for k in range(actions)],
        "config_toml": "",
    }
    return ks, bs, ss, nb, meta


@pytest.fixture
def policy(tmp_path):
    from jaxexo.storage.policy_file import save_policy

    ks, bs, ss, nb, meta = _layers()
    return save_policy(tmp_path / "policy.npz", ks, bs, ss, nb, meta)


def _files(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _write(path, files: dict, meta_update=None, drop=(), fix_checksum=True):
    files = dict(files)
    meta = json.loads(str(files.pop("metadata")))
    meta.update(meta_update or {})
    for k in drop:
        meta.pop(k, None)
    if fix_checksum:
        meta["sha256"] = policy_checksum(files, meta)
    np.savez(path, metadata=np.array(json.dumps(meta)), **files)
    return path


def test_policy_round_trip_and_checksum_in_metadata(policy):
    pol = load_policy(policy)
    ks, bs, ss, nb, _ = _layers()
    for a, b in zip(
        pol.kernels + pol.biases + pol.norm_scales + pol.norm_biases, ks + bs + ss + nb
    ):
        np.testing.assert_array_equal(a, b)
    files = _files(policy)
    meta = json.loads(str(files.pop("metadata")))
    assert meta["format_version"] == 2 and meta["sha256"] == policy_checksum(files, meta)


def test_policy_tampering_is_refused(policy, tmp_path):
    files = _files(policy)
    k1 = files["dense_1_kernel"]
    assert k1.shape[0] == k1.shape[1]  # square: a transposed kernel still fits the layer sizes
    flipped = files["dense_0_kernel"].copy()
    flipped.view(np.uint8)[:64] ^= 0xFF
    cases = {
        "transposed": ({**files, "dense_1_kernel": k1.T.copy()}, "checksum mismatch"),
        "flipped": ({**files, "dense_0_kernel": flipped}, "checksum mismatch"),
    }
    for name, (f, message) in cases.items():
        path = _write(tmp_path / f"{name}.npz", f, fix_checksum=False)
        with pytest.raises(PolicyFileError, match=message) as info:
            load_policy(path)
        assert str(path) in str(info.value)
    # Metadata changed without a new checksum: a different network (no LayerNorm) must not load.
    path = _write(tmp_path / "meta.npz", files, {"layer_norm": False}, fix_checksum=False)
    with pytest.raises(PolicyFileError, match="checksum mismatch"):
        load_policy(path)


@pytest.mark.parametrize(
    "case, message",
    [
        ("no_layer_norm", "metadata.layer_norm is missing"),
        ("no_activation", "metadata.activation is missing"),
        ("no_angles", "metadata.action_angles_rad is missing"),
        ("no_checksum", "metadata.sha256 is missing"),
        ("activation", "metadata.activation must be one of"),
        ("layer_norm_string", "metadata.layer_norm must be true or false"),
        ("layers_float", "metadata.layers must be"),
        ("obs_dim", "metadata.obs_dim is 6 but the network \\(metadata.layers\\) has 5 inputs"),
        ("null_layers", "metadata.layers is missing"),
        ("angles", "lists 35 angles for 36 actions"),
        ("int8", "'dense_0_kernel' has dtype int8"),
        ("complex", "'dense_1_bias' has dtype complex64"),
        ("float64_overflow", "'dense_2_kernel' holds NaN or inf after the cast to float32"),
        ("inf", "'norm_0_scale' holds NaN or inf"),
        ("extra_norm", "unexpected arrays"),
        ("version_1", "format_version 1"),
    ],
)
def test_policy_fields_and_dtypes_are_checked(policy, tmp_path, case, message):
    """Each file carries a valid checksum (recomputed): the check that refuses it is the one under test."""
    f = _files(policy)
    meta, drop = {}, ()
    if case.startswith("no_"):
        drop = (
            {
                "no_layer_norm": "layer_norm",
                "no_activation": "activation",
                "no_angles": "action_angles_rad",
                "no_checksum": "sha256",
            }[case],
        )
    elif case == "activation":
        meta = {"activation": "tanh"}
    elif case == "layer_norm_string":
        meta = {"layer_norm": "yes"}
    elif case == "layers_float":
        meta = {"layers": [5, 8.0, 8, 36]}
    elif case == "null_layers":
        meta = {"layers": None}
    elif case == "obs_dim":
        meta = {"obs_dim": 6}
    elif case == "angles":
        meta = {"action_angles_rad": [0.0] * 35}
    elif case == "int8":
        f["dense_0_kernel"] = f["dense_0_kernel"].astype(np.int8)
    elif case == "complex":
        f["dense_1_bias"] = f["dense_1_bias"].astype(np.complex64)
    elif case == "float64_overflow":
        k = f["dense_2_kernel"].astype(np.float64)
        k[3, 4] = 1e300  # finite in float64, inf in float32
        f["dense_2_kernel"] = k
    elif case == "inf":
        f["norm_0_scale"] = f["norm_0_scale"].copy()
        f["norm_0_scale"][2] = np.inf
    elif case == "extra_norm":
        meta = {"layer_norm": False}  # the norm arrays are then not part of the network
    elif case == "version_1":
        meta = {"format_version": 1}
    path = _write(tmp_path / "p.npz", f, meta, drop, fix_checksum=case != "no_checksum")
    with pytest.raises(PolicyFileError, match=message) as info:
        load_policy(path)
    assert str(path) in str(info.value)


def test_save_policy_refuses_non_finite_weights(tmp_path):
    from jaxexo.storage.policy_file import save_policy

    ks, bs, ss, nb, meta = _layers()
    ks[1] = ks[1].copy()
    ks[1][0, 0] = np.nan
    with pytest.raises(PolicyFileError, match="'dense_1_kernel' holds NaN or inf"):
        save_policy(tmp_path / "policy.npz", ks, bs, ss, nb, meta)
    ks, *_ = _layers()
    big = [k.astype(np.float64) for k in ks]
    big[0][0, 0] = 1.6e39  # beyond float32
    with pytest.raises(PolicyFileError, match="after the cast to float32"):
        save_policy(tmp_path / "policy.npz", big, bs, ss, nb, meta)
    assert list(tmp_path.iterdir()) == []  # nothing written, no temporary file


# --------------------------------------------------------------------------------------------
# Run directories: the lock and the empty-directory rule
# --------------------------------------------------------------------------------------------


def test_run_lock_is_exclusive_and_released(tmp_path):
    with run_lock(tmp_path / "d", "train"):
        with pytest.raises(
            RunDirError, match=f"in use by another jaxexo process \\(pid {os.getpid()}"
        ):
            with run_lock(tmp_path / "d", "train"):
                pass
    with run_lock(tmp_path / "d", "train"):  # released at the end of the block
        pass
    with pytest.raises(RunDirError, match="no checkpoint to resume from"):
        with run_lock(tmp_path / "absent", "train", create=False):
            pass
    assert not (tmp_path / "absent").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunDirError, match="is a file"):
        with run_lock(tmp_path / "file", "train"):
            pass


def test_lock_of_a_killed_process_does_not_block(tmp_path):
    code = (
        "import sys, time; from jaxexo.storage.rundir import run_lock\n"
        "with run_lock(sys.argv[1], 'train'):\n    print('locked', flush=True); time.sleep(600)\n"
    )
    p = subprocess.Popen(
        [sys.executable, "-c", code, str(tmp_path / "d")],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        assert p.stdout.readline().strip() == "locked"
        with pytest.raises(RunDirError, match=f"pid {p.pid}"):
            with run_lock(tmp_path / "d", "train"):
                pass
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait()
    assert (tmp_path / "d" / LOCK_NAME).exists()  # left behind...
    with run_lock(tmp_path / "d", "train"):  # ...and no obstacle
        pass


def test_cli_train_and_sweep_refuse_a_locked_directory(tmp_path):
    """A second process (the CLI) on a directory this process holds: refused at once, nothing written."""
    cfg_path = tmp_path / "tiny.toml"
    cfg_path.write_text(config_to_toml(tiny_config()))
    run = tmp_path / "run"
    with run_lock(run, "train"):
        r = run_cli("train", cfg_path, "--out", run, "--quiet", env=one_device_env())
        assert_clean_refusal(r, str(run), "in use by another jaxexo process", f"pid {os.getpid()}")
        assert snapshot(run) == {}
        r = run_cli(
            "sweep",
            ROOT / "configs" / "sweeps" / "smoke.toml",
            "--out",
            run,
            "--quiet",
            env=one_device_env(),
        )
        assert_clean_refusal(r, str(run), "in use by another jaxexo process")
        assert snapshot(run) == {}


@pytest.mark.parametrize(
    "present", [("policy.npz",), ("eval.json", "metrics.jsonl"), ("policy.npz", "config.toml")]
)
def test_new_run_refuses_a_directory_with_results_but_no_checkpoint(tmp_path, present):
    """A sweep's best/, a run whose checkpoint was deleted, the remains of a crashed run: never
    overwritten or appended to."""
    jax = pytest.importorskip("jax")  # noqa: F841
    from jaxexo.train.driver import run_training

    run = tmp_path / "run"
    run.mkdir()
    for name in present:
        (run / name).write_bytes(b"precious " + name.encode())
    before = snapshot(run)
    with pytest.raises(
        ConfigError,
        match="is not empty .*" + present[0].replace(".", r"\.") + ".*no checkpoint"
        r"\.msgpack to resume",
    ):
        run_training(tiny_config(), run, seed=SEED, progress=False)
    assert snapshot(run) == before


def test_sweep_refuses_a_directory_with_other_files(tmp_path):
    pytest.importorskip("jax")
    from jaxexo.sweep.runner import run_sweep
    from jaxexo.sweep.spec import load_sweep

    run = tmp_path / "best"
    run.mkdir()
    (run / "policy.npz").write_bytes(b"precious")
    with pytest.raises(ConfigError, match="not empty \\(policy.npz\\) and holds no sweep"):
        run_sweep(load_sweep(ROOT / "configs" / "sweeps" / "smoke.toml"), run, progress=False)
    assert snapshot(run) == {"policy.npz": b"precious"}


# --------------------------------------------------------------------------------------------
# generate: unclear errors made clear
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--out", "{d}/", "is a directory"),
        ("--out", "{d}", "is a directory"),
        ("--json", "{d}/missing/t.json", "does not exist"),
        ("--plot", "{d}", "is a directory"),
    ],
)
def test_cli_generate_refuses_directories_and_missing_folders(tmp_path, option, value, message):
    d = tmp_path / "outdir"
    d.mkdir()
    outputs = {"--out": tmp_path / "t.csv", option: value.format(d=d)}
    args = ["generate", "--method", "cfftg", "--obstacle", "triangle"] + [
        x for kv in outputs.items() for x in kv
    ]
    r = run_cli(*args, timeout=120)
    assert_clean_refusal(r, option, message)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "outdir"
    ]  # nothing written, no stray .tmp
    assert list(d.iterdir()) == []


# --------------------------------------------------------------------------------------------
# Integer counters (no float32 drift past 2^24)
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_counters_are_exact_past_2_24_with_an_odd_rollout_size():
    """N T = 12 x 7 = 84 (not a power of two) and a budget just past 2^24 env steps: the run stops after
    exactly ceil(budget / 84) updates, the env-step and episode counts are exact integers (Python's
    integer arithmetic is the reference). In float32 neither 2^24 + 1 episodes nor the step count
    near the budget is representable."""
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from jaxexo.train.trainer import METRICS, Hyperparams, Trainer

    budget = 2**24 + 1000
    cfg = tiny_config(
        num_envs=12, rollout_steps=7, num_minibatches=1, hidden=[8], budget_env_steps=budget
    )
    trainer = Trainer(cfg)
    hyper = Hyperparams.from_config(cfg)
    per = 12 * 7
    last = -(-budget // per)  # updates the budget allows
    assert (last - 1) * per < budget <= last * per and int(hyper.budget_updates) == last
    active = jax.jit(trainer.active)
    ts = jax.jit(trainer.init)(jax.random.PRNGKey(0), hyper)
    episodes0 = 2**24 + 1
    ts = ts.replace(
        update=jnp.asarray(last - 2, jnp.int32), episodes=jnp.asarray(episodes0, jnp.int32)
    )
    assert bool(active(ts, hyper))
    ts, m = jax.jit(trainer.run, static_argnums=2)(ts, hyper, 3)
    m = np.stack([np.asarray(getattr(m, k)) for k in METRICS], axis=-1)
    col = {k: i for i, k in enumerate(METRICS)}
    assert (m[:, col["env_steps"]] > 0).tolist() == [
        True,
        True,
        False,
    ]  # two updates left, then frozen
    assert int(ts.update) == last and not bool(active(ts, hyper))
    assert int(trainer.env_steps(ts)) == last * per
    assert int(ts.episodes) == episodes0 + int(m[:, col["episodes"]].sum())
    assert ts.episodes.dtype == jnp.int32 and ts.update.dtype == jnp.int32
    # Episode budgets in integers too: 2^24 + 2 and 2^24 + 3 are one episode apart (equal in float32).
    hyper_ep = hyper.replace(
        budget_episodes=jnp.asarray(2**24 + 3, jnp.int32), budget_updates=jnp.asarray(0, jnp.int32)
    )
    assert bool(active(ts.replace(episodes=jnp.asarray(2**24 + 2, jnp.int32)), hyper_ep))
    assert not bool(active(ts.replace(episodes=jnp.asarray(2**24 + 3, jnp.int32)), hyper_ep))


# --------------------------------------------------------------------------------------------
# Training runs: divergence, foreign checkpoints, kill/resume, two writers, full disk (slow)
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def reference(tiny_reference):
    """The uninterrupted tiny run by the CLI on one device (what every interrupted run must equal):
    the session's (conftest.tiny_reference), whose config is this module's tiny config."""
    assert tiny_reference["cfg"] == tiny_config()
    return {"run": tiny_reference["run"], "cfg_path": tiny_reference["cfg_path"]}


def assert_same_run(a, b):
    """Bit-identical results: checkpoint, policy arrays, metrics counters, evaluation."""
    from jaxexo.train.run_dir import CHECKPOINT

    assert (a / CHECKPOINT).read_bytes() == (b / CHECKPOINT).read_bytes()
    pa, pb = _files(a / "policy.npz"), _files(b / "policy.npz")
    assert sorted(pa) == sorted(pb)
    for k in pa:
        assert pa[k].dtype == pb[k].dtype and np.array_equal(pa[k], pb[k]), k
    assert metrics_without_clock(a / "metrics.jsonl") == metrics_without_clock(b / "metrics.jsonl")
    drop = lambda r: {k: v for k, v in r.items() if k != "train_seconds"}  # noqa: E731
    assert drop(json.loads((a / "eval.json").read_text())) == drop(
        json.loads((b / "eval.json").read_text())
    )


@pytest.mark.slow
def test_resume_refuses_foreign_corrupt_and_incomplete_run_directories(reference, tmp_path):
    from flax import serialization

    from jaxexo.train.checkpoints import read_checkpoint
    from jaxexo.train.driver import run_training
    from jaxexo.train.run_dir import CHECKPOINT

    cfg = tiny_config()
    run = tmp_path / "run"
    shutil.copytree(reference["run"], run)
    ckpt = run / CHECKPOINT
    good = ckpt.read_bytes()
    raw = read_checkpoint(ckpt)
    assert raw["book"]["chunks_done"] == 3
    # 64 flipped bytes in the payload: refused (it used to resume and export a weight of 1.6e38).
    bad = bytearray(good)
    for i in np.random.default_rng(1).choice(np.arange(200, len(good)), 64, replace=False):
        bad[i] ^= 0xFF
    ckpt.write_bytes(bytes(bad))
    with pytest.raises(CheckpointError, match=f"{ckpt}: checksum mismatch"):
        run_training(cfg, run, seed=SEED, resume=True, progress=False)
    ckpt.write_bytes(good[:1000])
    with pytest.raises(CheckpointError, match=f"{ckpt}: checksum mismatch"):
        run_training(cfg, run, seed=SEED, resume=True, progress=False)
    # A valid envelope around msgpack garbage, and around another network's checkpoint.
    ckpt.write_bytes(pack_checkpoint(b"\xc1\xc1\xc1 not msgpack"))
    with pytest.raises(CheckpointError, match="cannot be decoded"):
        run_training(cfg, run, seed=SEED, resume=True, progress=False)
    payload = serialization.msgpack_restore(unpack_checkpoint(good, ckpt))
    layers = payload["state"]["params"]["params"]
    first = sorted(layers)[0]
    k = layers[first]["kernel"]
    layers[first]["kernel"] = np.zeros(
        (k.shape[0] + 1,) + k.shape[1:], np.float32
    )  # another network's shape
    ckpt.write_bytes(pack_checkpoint(serialization.msgpack_serialize(payload)))
    with pytest.raises(CheckpointError, match=f"{ckpt}: does not fit this config's training state"):
        run_training(cfg, run, seed=SEED, resume=True, progress=False)
    # config.toml missing: say that, not "no checkpoint".
    ckpt.write_bytes(good)
    (run / "config.toml").unlink()
    with pytest.raises(ConfigError, match="has checkpoint.msgpack but no config.toml"):
        run_training(cfg, run, seed=SEED, resume=True, progress=False)
    # Nothing of the run was changed by the refusals.
    assert ckpt.read_bytes() == good
    for name in ("policy.npz", "metrics.jsonl", "eval.json"):
        assert (run / name).read_bytes() == (reference["run"] / name).read_bytes(), name


@pytest.mark.slow
def test_sigkill_mid_run_then_resume_is_bit_identical(reference, tmp_path):
    cfg_path = reference["cfg_path"]
    run = tmp_path / "run"
    p = start_training(cfg_path, run, stdout=subprocess.DEVNULL)
    t0 = time.monotonic()
    while not (run / "checkpoint.msgpack").exists():
        assert p.poll() is None, p.stderr.read()[-3000:]
        assert time.monotonic() - t0 < 600
        time.sleep(0.01)
    p.send_signal(signal.SIGKILL)
    p.communicate()
    assert p.returncode == -signal.SIGKILL  # killed, not finished
    assert not (run / "eval.json").exists()
    assert (run / LOCK_NAME).exists()  # the dead process's lock file is still there
    r = run_cli(
        "train",
        cfg_path,
        "--out",
        run,
        "--quiet",
        "--seed",
        SEED,
        "--resume",
        env=one_device_env(),
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert_same_run(reference["run"], run)
    assert not any(p.name.endswith(".tmp") for p in run.iterdir())


@pytest.mark.slow
def test_run_stopped_before_its_first_checkpoint_resumes_from_scratch(reference, tmp_path):
    """Killed (here: interrupted) after chunk 1's metrics row but before its checkpoint: a new run there is
    refused (it is not empty) with a hint, --resume starts again and ends as the uninterrupted run."""
    from jaxexo.train import checkpoints, driver

    cfg = tiny_config()
    run = tmp_path / "run"

    def interrupt(path, data):
        raise KeyboardInterrupt

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(checkpoints, "checkpoint_write", interrupt)
        with pytest.raises(KeyboardInterrupt):
            driver.run_training(cfg, run, seed=SEED, progress=False)
    # as a SIGKILL mid-write leaves it (atomic_write's temporary name for checkpoint.msgpack)
    (run / ".checkpoint.msgpack.k1ll3d.tmp").write_bytes(b"half a checkpoint")
    assert sorted(snapshot(run)) == [
        ".checkpoint.msgpack.k1ll3d.tmp",
        "config.toml",
        "metrics.jsonl",
    ]
    with pytest.raises(ConfigError, match="--resume starts it again"):
        driver.run_training(cfg, run, seed=SEED, progress=False)
    with pytest.raises(ConfigError, match="config differs"):
        driver.run_training(tiny_config(lr=5e-4), run, seed=SEED, resume=True, progress=False)
    driver.run_training(cfg, run, seed=SEED, resume=True, progress=False)
    assert not (run / ".checkpoint.msgpack.k1ll3d.tmp").exists()
    assert_same_run(reference["run"], run)


@pytest.mark.slow
def test_two_training_processes_on_one_directory(reference, tmp_path):
    """Started together: one trains, the other is refused (in use, or already holds a run if the first
    was faster) with a clean message; the run is exactly the uninterrupted one, no interleaved rows."""
    cfg_path = reference["cfg_path"]
    run = tmp_path / "run"
    procs = [start_training(cfg_path, run, stdout=subprocess.PIPE) for _ in range(2)]
    results = [(p, *p.communicate(timeout=900)) for p in procs]
    codes = sorted(p.returncode for p, _, _ in results)
    assert codes == [0, 2], [(p.returncode, err[-1500:]) for p, _, err in results]
    loser = next(err for p, _, err in results if p.returncode == 2)
    assert "Traceback" not in loser and str(run) in loser
    assert "in use by another jaxexo process" in loser or "already holds a run" in loser, loser
    assert_same_run(reference["run"], run)


@pytest.mark.slow
def test_full_disk_fails_cleanly_and_keeps_the_last_checkpoint(reference, tmp_path):
    """Chunk 1 checkpointed; the resumed process may not write files as large as a checkpoint: it fails
    on chunk 2's checkpoint with a message naming the file (exit 1, no traceback), the chunk-1 checkpoint
    is intact, no temporary file is left, and a later resume ends bit-identical to the uninterrupted run."""
    from jaxexo.train import checkpoints, driver, run_dir

    cfg = tiny_config()
    run = tmp_path / "run"
    calls = {"n": 0}
    real = checkpoints.checkpoint_write

    def stop_after_chunk_1(path, data):  # checkpoint, bookkeeping of chunk 1, then stop
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(path, data)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(checkpoints, "checkpoint_write", stop_after_chunk_1)
        with pytest.raises(KeyboardInterrupt):
            driver.run_training(cfg, run, seed=SEED, progress=False)
    ckpt = run / run_dir.CHECKPOINT
    saved = ckpt.read_bytes()
    assert checkpoints.read_checkpoint(ckpt)["book"]["chunks_done"] == 1
    r = subprocess.run(
        limited_fsize(
            len(saved) - 1,
            cli_cmd(
                "train", reference["cfg_path"], "--out", run, "--quiet", "--seed", SEED, "--resume"
            ),
        ),
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=without_compilation_cache(one_device_env()),
        timeout=900,
    )
    assert_clean_refusal(r, f"could not write {ckpt}", "File too large", code=1)
    assert ckpt.read_bytes() == saved
    assert not any(p.name.endswith(".tmp") for p in run.iterdir())
    assert not (run / "policy.npz").exists()
    driver.run_training(cfg, run, seed=SEED, resume=True, progress=False)
    assert_same_run(reference["run"], run)


@pytest.mark.slow
def test_diverged_run_says_so_and_exports_nothing_non_finite(tmp_path):
    """train.lr = 1e9 (the issue's case): a non-zero exit with a message, a ``diverged`` row, no policy
    (no chunk had finite parameters) and no checkpoint of the diverged state."""
    cfg = tiny_config(lr=1e9)
    cfg_path = tmp_path / "lr.toml"
    cfg_path.write_text(config_to_toml(cfg))
    run = tmp_path / "run"
    r = subprocess.run(
        cli_cmd("train", cfg_path, "--out", run, "--quiet", "--seed", SEED),
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=one_device_env(),
        timeout=900,
    )
    assert_clean_refusal(r, "training diverged in chunk 1", "train.lr", code=3)

    def strict(constant):  # NaN, Infinity: not JSON
        raise AssertionError(f"metrics.jsonl holds {constant}, which is not JSON")

    lines = (run / "metrics.jsonl").read_text().splitlines()
    rows = [json.loads(x, parse_constant=strict) for x in lines]
    (agent,) = rows[0]["members"]
    assert [x["members"][0]["diverged"] for x in rows] == [True]
    assert agent["validation_success_raw"] is None
    assert not (run / "policy.npz").exists() and not (run / "checkpoint.msgpack").exists()


@pytest.mark.slow
def test_divergence_after_a_good_chunk_keeps_the_best_finite_parameters(tmp_path, monkeypatch):
    """Parameters that turn NaN in chunk 2 (injected after the real update): chunk 1's parameters, the best
    finite ones, are exported and evaluated, the checkpoint stays at chunk 1, and TrainingDiverged is raised."""
    import jax
    import jax.numpy as jnp

    from jaxexo.train import checkpoints, driver, run_dir
    from jaxexo.train.trainer import Trainer

    real_run = Trainer.run

    def run_then_poison(self, ts, hyper, n):
        ts, m = real_run(self, ts, hyper, n)
        bad = ts.update > 2
        return ts.replace(params=jax.tree.map(lambda p: jnp.where(bad, jnp.nan, p), ts.params)), m

    monkeypatch.setattr(Trainer, "run", run_then_poison)
    run = tmp_path / "run"
    with pytest.raises(
        driver.TrainingDiverged, match="diverged in chunk 2.*best finite parameters, from chunk 1"
    ):
        driver.run_training(tiny_config(), run, seed=SEED, progress=False)
    rows = [json.loads(x) for x in (run / "metrics.jsonl").read_text().splitlines()]
    assert [x["members"][0]["diverged"] for x in rows] == [False, True]
    assert checkpoints.read_checkpoint(run / run_dir.CHECKPOINT)["book"]["chunks_done"] == 1
    pol = load_policy(run / "policy.npz")
    assert all(np.all(np.isfinite(k)) for k in pol.kernels)
    res = json.loads((run / "eval.json").read_text())
    assert res["selected_chunk"] == 1 and res["members"][0]["diverged_chunk"] == 2
    # The exported network is chunk 1's (the checkpoint's best parameters): the same Q-values.
    best = checkpoints.read_checkpoint(run / run_dir.CHECKPOINT)["best_params"]
    best = jax.tree.map(lambda x: x[0], best)  # the agent axis: one agent is a population of one
    trainer = Trainer(tiny_config())
    obs = np.random.default_rng(0).normal(size=(64, trainer.env.obs_dim)).astype(np.float32)
    np.testing.assert_allclose(
        pol.q_values(obs), np.asarray(trainer.net.apply(best, obs)), rtol=1e-5, atol=1e-5
    )


@pytest.mark.slow
def test_resume_refuses_an_edited_config_a_deleted_checkpoint_and_undecodable_metrics(
    reference, tmp_path
):
    """config.toml edited together with the config passed (a changed lr would mix two
    learning rates), checkpoint.msgpack deleted from a run of several chunks (it used to restart from
    scratch silently), random bytes in metrics.jsonl (named, not "'utf-8' codec can't decode")."""
    from jaxexo.train.driver import run_training
    from jaxexo.train.run_dir import BOOKKEEPING, CHECKPOINT

    run = tmp_path / "run"
    shutil.copytree(reference["run"], run)
    edited = tiny_config(lr=5e-4)
    (run / "config.toml").write_text(config_to_toml(edited))
    with pytest.raises(
        ConfigError,
        match=r"the config differs from the run's config recorded in .*checkpoint.msgpack in train.lr",
    ):
        run_training(edited, run, seed=SEED, resume=True, progress=False)
    (run / "config.toml").write_bytes((reference["run"] / "config.toml").read_bytes())

    good = (run / "metrics.jsonl").read_bytes()
    (run / "metrics.jsonl").write_bytes(np.random.default_rng(0).bytes(300))
    with pytest.raises(ConfigError, match=f"{run / 'metrics.jsonl'} is damaged"):
        run_training(tiny_config(), run, seed=SEED, resume=True, progress=False)
    (run / "metrics.jsonl").write_bytes(good)

    (run / CHECKPOINT).unlink()
    with pytest.raises(ConfigError, match="checkpoint was deleted"):
        run_training(tiny_config(), run, seed=SEED, resume=True, progress=False)
    for name in (BOOKKEEPING, "policy.npz", "eval.json", "training_curve.png"):
        (run / name).unlink()
    with pytest.raises(ConfigError, match="metrics.jsonl records 3 finished chunks"):
        run_training(tiny_config(), run, seed=SEED, resume=True, progress=False)
    with pytest.raises(
        ConfigError, match="is not empty"
    ) as info:  # a new run there: no restart hint
        run_training(tiny_config(), run, seed=SEED, progress=False)
    assert "--resume starts it again" not in str(info.value)
    assert (run / "metrics.jsonl").read_bytes() == good
