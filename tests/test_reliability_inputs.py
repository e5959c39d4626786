"""Nothing lost: no file outside the run touched, no input overwritten by an
output, no setting that silently means something else, every bad input refused before any work with
one line naming the field, option or file (no traceback, no kill for memory).

Fast: no training (the one CLI run that reaches training stops at its lock); subprocesses only where
the exit code and stderr are what is checked. docs/reliability.md lists these cases.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict
from jaxexo.storage.atomic import SymlinkRefused, append_line
from jaxexo.storage.rundir import LOCK_NAME, RunDirError, run_lock

from conftest import ROOT, run_cli


def assert_clean_refusal(r: subprocess.CompletedProcess, *needles: str, code: int = 2):
    """Non-zero exit, one line ``jaxexo: error`` naming what is wrong, and no traceback."""
    assert r.returncode == code, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "jaxexo: error:" in r.stderr, r.stderr[-2000:]
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr[-2000:]
    for n in needles:
        assert n in r.stderr, (n, r.stderr[-2000:])


# --------------------------------------------------------------------------------------------
# No file outside the run reached through a symbolic link
# --------------------------------------------------------------------------------------------


def test_a_symlinked_lock_file_is_refused_and_its_target_untouched(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    run = tmp_path / "run"
    run.mkdir()
    (run / LOCK_NAME).symlink_to(victim)
    with pytest.raises(RunDirError, match="symbolic link"):
        with run_lock(run, "train"):
            pass
    assert victim.read_text() == "precious\n"
    cfg = tmp_path / "tiny.toml"
    cfg.write_text("[train]\nbudget_env_steps = 1024\nnum_envs = 64\npopulation = 1\n")
    r = run_cli("train", cfg, "--out", run, "--quiet")
    assert_clean_refusal(r, "--out", LOCK_NAME, "symbolic link")
    assert victim.read_text() == "precious\n"


def test_a_run_directory_below_a_file_is_refused_naming_the_file(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x\n")
    with pytest.raises(RunDirError, match=f"--out: {afile} is a file, not a folder"):
        with run_lock(afile / "run", "train"):
            pass
    assert afile.read_text() == "x\n"


def test_an_append_only_log_replaced_by_a_symlink_is_refused(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    log = tmp_path / "metrics.jsonl"
    log.symlink_to(victim)
    with pytest.raises(SymlinkRefused, match="metrics.jsonl is a symbolic link"):
        append_line(log, "{}\n")
    assert victim.read_text() == "precious\n"


# --------------------------------------------------------------------------------------------
# A policy file made without training (random weights, a real config): the generator loads it
# --------------------------------------------------------------------------------------------


def make_policy(path, cfg=None, seed=0, **meta_changes):
    from jaxexo.config import load_config
    from jaxexo.config.toml_io import config_to_toml
    from jaxexo.physics import actions
    from jaxexo.storage.policy_file import save_policy

    cfg = cfg or load_config(ROOT / "configs" / "quick.toml")
    rng = np.random.default_rng(seed)
    sizes = [
        actions.obs_dim(cfg.env.obs_mode, cfg.env.shape_points),
        *cfg.train.hidden,
        actions.NUM_ACTIONS,
    ]
    ks = [
        rng.normal(scale=0.1, size=(a, b)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:])
    ]
    bs = [np.zeros(b, np.float32) for b in sizes[1:]]
    hidden = list(cfg.train.hidden) if cfg.train.layer_norm else []
    meta = {
        "obs_mode": cfg.env.obs_mode,
        "obs_dim": sizes[0],
        "num_actions": sizes[-1],
        "layers": sizes,
        "layer_norm": cfg.train.layer_norm,
        "activation": "relu",
        "length_scale": actions.LENGTH_SCALE,
        "thesis_obs_center": list(actions.THESIS_OBS_CENTER),
        "action_angles_rad": actions.action_angles().tolist(),
        "config_toml": config_to_toml(cfg),
    }
    meta.update(meta_changes)
    return save_policy(
        path,
        ks,
        bs,
        [np.ones(h, np.float32) for h in hidden],
        [np.zeros(h, np.float32) for h in hidden],
        meta,
    )


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    return make_policy(tmp_path_factory.mktemp("policy") / "policy.npz")


@pytest.fixture(scope="module")
def generator(policy):
    from jaxexo.inference import TrajectoryGenerator

    return TrajectoryGenerator.load(policy)


# --------------------------------------------------------------------------------------------
# Outputs never replace inputs, nor each other (jaxexo generate, jaxexo eval)
# --------------------------------------------------------------------------------------------

GEN = ("generate", "--obstacle", "base1")


@pytest.mark.parametrize(
    "outputs",
    [
        lambda d, p: ["--out", p],
        lambda d, p: ["--out", d / "t.csv", "--json", p],
        lambda d, p: ["--out", d / "t.csv", "--plot", p],
        lambda d, p: ["--out", d / "link.csv"],  # a symbolic link to the policy
        lambda d, p: ["--out", d / "x", "--json", d / "x"],
        lambda d, p: ["--out", d / "t.csv", "--plot", d / "s.png", "--json", d / "s.png"],
        lambda d, p: ["--out", d / "t.csv", "--json", d / "a.gif", "--animate", d / "a.gif"],
    ],
)
def test_generate_refuses_an_output_on_an_input_or_on_another_output(tmp_path, outputs):
    policy = make_policy(tmp_path / "p.npz")
    (tmp_path / "link.csv").symlink_to(policy)
    before = policy.read_bytes()
    r = run_cli(*GEN, "--policy", policy, *outputs(tmp_path, policy))
    assert_clean_refusal(r)
    assert ("input" in r.stderr) or ("also the" in r.stderr), r.stderr
    assert policy.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.csv", "p.npz"]  # nothing written


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--out", "{f}/t.csv"], ["--out", "is a file, not a folder"]),
        (["--out", "t.csv", "--json", "{f}/sub/t.json"], ["--json", "is a file, not a folder"]),
        (["--out", "t.csv", "--duration", "1e300"], ["--duration", "<= 60 s"]),
        (["--out", "t.csv", "--duration", "0"], ["--duration", "> 0"]),
        (["--out", "t.csv", "--points", "100000000"], ["--points"]),
        (["--out", "t.csv", "--rate", "100000"], ["--rate", "10000 Hz"]),
        (["--out", "t.csv", "--rate", "1e9"], ["--rate"]),
        (["--out", "t.csv", "--method", "cfftg", "--smoothing", "0.1"], ["--smoothing", "rl only"]),
    ],
)
def test_generate_refuses_bad_options_before_any_work(tmp_path, args, needles):
    afile = tmp_path / "afile"
    afile.write_text("not a folder\n")
    args = [
        a.format(f=afile) if "{f}" in a else (tmp_path / a if a.endswith((".csv", ".json")) else a)
        for a in args
    ]
    r = (
        run_cli(*GEN, "--method", "cfftg", *args)
        if "--method" not in args
        else run_cli(*GEN, *args)
    )
    assert_clean_refusal(r, *needles)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_generate_accepts_a_pivot_y_alone_and_cfftg_without_smoothing(tmp_path):
    r = run_cli(*GEN, "--method", "cfftg", "--pivot-y", "0.3", "--out", tmp_path / "t.csv")
    assert r.returncode in (0, 1), r.stderr[-2000:]
    assert (tmp_path / "t.csv").exists() and "pivot" in r.stdout


def test_eval_refuses_to_overwrite_its_input_or_an_earlier_report(tmp_path):
    out = tmp_path / "report"
    out.mkdir()
    policy = make_policy(out / "report.json")
    before = policy.read_bytes()
    r = run_cli("eval", "--policy", policy, "--out", out, "--n", 1, "--no-figures")
    assert_clean_refusal(r, "--out", "input")
    assert policy.read_bytes() == before
    # an earlier report: refused unless --force
    policy2 = make_policy(tmp_path / "p.npz")
    (out / "report.md").write_text("earlier\n")
    other = tmp_path / "other"
    other.mkdir()
    (other / "report.md").write_text("earlier\n")
    r = run_cli("eval", "--policy", policy2, "--out", other, "--n", 1, "--no-figures")
    assert_clean_refusal(r, "--out", "already holds a report", "--force")
    assert (other / "report.md").read_text() == "earlier\n"
    # --out naming a file
    afile = tmp_path / "afile"
    afile.write_text("x\n")
    r = run_cli("eval", "--policy", policy2, "--out", afile, "--n", 1, "--no-figures")
    assert_clean_refusal(r, "--out", "is a file, not a folder")
    assert afile.read_text() == "x\n"


def test_eval_force_replaces_an_earlier_report(tmp_path, policy):
    from jaxexo.evaluation.compare import run_eval

    out = tmp_path / "r"
    run_eval(policy, out, against=None, n=2, figures=False, batch_size=2)
    with pytest.raises(ValueError, match="already holds a report"):
        run_eval(policy, out, against=None, n=2, figures=False, batch_size=2)
    run_eval(policy, out, against=None, n=2, figures=False, batch_size=2, force=True)
    assert json.loads((out / "report.json").read_text())["rl"]["n"] == 2


def test_reproduce_validates_every_option_before_training(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x\n")
    for args, needles in (
        (["--models", "a", "--n", "0"], ["--n", "from 1 to"]),
        (["--models", "a", "--results", afile], ["--results", "is a file, not a folder"]),
        (["--models", "a", "--results", afile / "sub"], ["--results", "is a file"]),
    ):
        r = run_cli("reproduce", "--out", tmp_path / "rep", *args, timeout=120)
        assert_clean_refusal(r, *needles)
        assert not (tmp_path / "rep").exists()  # nothing trained, nothing written


# --------------------------------------------------------------------------------------------
# Policy files: what is not a policy says so; the config is the policy's own
# --------------------------------------------------------------------------------------------


def test_a_non_policy_file_is_not_a_jaxexo_policy_and_pickle_is_never_suggested(tmp_path):
    from jaxexo.storage.policy_file import PolicyFileError, load_policy

    png = tmp_path / "image.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)
    rnd = tmp_path / "random.npz"
    rnd.write_bytes(np.random.default_rng(0).bytes(4096))
    for path in (png, rnd):
        with pytest.raises(PolicyFileError, match="not a jaxexo policy") as info:
            load_policy(path)
        assert "pickle" not in str(info.value) and str(path) in str(info.value)
    r = run_cli(*GEN, "--policy", png, "--out", tmp_path / "t.csv")
    assert_clean_refusal(r, "not a jaxexo policy", str(png))
    assert "pickle" not in r.stderr


def test_an_npz_header_claiming_a_huge_shape_is_refused_before_allocating(tmp_path):
    import zipfile

    from jaxexo.storage.policy_file import PolicyFileError, load_policy

    header = {"descr": "<f4", "fortran_order": False, "shape": (10**6, 10**6)}
    buf = __import__("io").BytesIO()
    np.lib.format.write_array_header_1_0(buf, header)
    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("metadata.npy", buf.getvalue() + b"\0" * 64)
    with pytest.raises(PolicyFileError, match="claims shape") as info:
        load_policy(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"config_toml": ""}, "config_toml is empty"),
        ({"config_toml": '[env]\nobs_mode = "conditioned"\n'}, "is not stated"),
        ({"obs_mode": "thesis"}, "metadata.obs_mode .* contradicts .* env.obs_mode"),
        ({"layer_norm": False}, "metadata.layer_norm .* contradicts .* train.layer_norm"),
    ],
)
def test_policy_config_must_be_complete_and_agree_with_the_metadata(tmp_path, changes, message):
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.storage.policy_file import PolicyFileError

    path = make_policy(tmp_path / "p.npz", **changes)
    if changes.get("layer_norm") is False:  # the arrays of a network without LayerNorm
        from jaxexo.storage.policy_file import policy_checksum

        with np.load(path) as z:
            files = {k: z[k] for k in z.files if not k.startswith("norm_")}
        meta = json.loads(str(files.pop("metadata")))
        meta["sha256"] = policy_checksum(files, meta)
        np.savez(path, metadata=np.array(json.dumps(meta)), **files)
    with pytest.raises(PolicyFileError, match=message):
        TrajectoryGenerator.load(path)


def test_a_policy_trained_before_the_floor_rule_loads_without_it(tmp_path):
    """A file written before env.floor_clearance existed (its config lacks the line) reads 0: the
    shield it was trained with; a file of today states it and keeps it."""
    from jaxexo.config import Config
    from jaxexo.config.toml_io import config_to_toml
    from jaxexo.inference import TrajectoryGenerator

    text = config_to_toml(Config())
    assert "floor_clearance = 0.02\n" in text
    old = make_policy(
        tmp_path / "old.npz", cfg=Config(), config_toml=text.replace("floor_clearance = 0.02\n", "")
    )
    assert TrajectoryGenerator.load(old).config.env.floor_clearance == 0.0
    new = make_policy(tmp_path / "new.npz", cfg=Config())
    assert TrajectoryGenerator.load(new).config.env.floor_clearance == 0.02


# --------------------------------------------------------------------------------------------
# The Python API: types checked, sizes bounded, raw errors replaced by ones naming the argument
# --------------------------------------------------------------------------------------------


def test_strings_and_booleans_are_never_taken_as_numbers(generator):
    from jaxexo.inference import Obstacle
    from jaxexo.swing.timing import time_swing

    for call, name in (
        (lambda: Obstacle.rectangle("0.1", 0.1), "width"),
        (lambda: Obstacle.profile([[0.3, 0.0], [0.4, "0.1"], [0.5, 0.0]]), "points"),
        (lambda: generator.generate(Obstacle.named("base1"), start_y="0.0"), "start_y"),
        (lambda: generator.generate(Obstacle.named("base1"), smoothing="0.1"), "smoothing"),
        (lambda: generator.generate(Obstacle.named("base1"), duration="1"), "duration"),
    ):
        with pytest.raises(ValueError, match=f"{name} must be .*string"):
            call()
    traj = generator.generate(Obstacle.named("base1"))
    for rate in ("100", True, None.__class__):
        with pytest.raises(TypeError, match="rate: expected a number in Hz"):
            time_swing(traj, generator.config, rate=rate)


def test_pivot_and_pivot_y_together_are_refused(generator):
    from jaxexo.baselines import CFFTG
    from jaxexo.inference import Obstacle

    ob = Obstacle.named("base1")
    for gen in (generator, CFFTG(generator.config)):
        with pytest.raises(ValueError, match="pivot, pivot_y: give one of them"):
            gen.generate(ob, pivot="agent", pivot_y=0.3)
        with pytest.raises(ValueError, match="pivot, pivot_y"):
            gen.generate_batch([ob, ob], pivot="obstacle", pivot_y=0.3)
        assert gen.generate(ob, pivot_y=0.3).scene.pivot_y == pytest.approx(0.3)
        assert gen.generate(ob).scene.pivot == "obstacle"


def test_public_api_names_the_argument_instead_of_a_raw_error(generator):
    from jaxexo.baselines import CFFTG
    from jaxexo.config import load_config
    from jaxexo.inference import Obstacle
    from jaxexo.swing.timing import time_swing, time_swings

    ob = Obstacle.named("base1")
    traj = generator.generate(ob)
    with pytest.raises(TypeError, match="config: expected a jaxexo Config"):
        time_swing(traj, None)
    with pytest.raises(TypeError, match="traj: expected one Trajectory"):
        time_swing(None, generator.config)
    with pytest.raises(TypeError, match="trajs: expected a list .* got one trajectory"):
        time_swings(traj, generator.config)
    with pytest.raises(TypeError, match=r"trajs\[1\]: expected a Trajectory"):
        time_swings([traj, None], generator.config)
    with pytest.raises(TypeError, match="obstacles: expected a list .* got one Obstacle"):
        generator.generate_batch(ob)
    with pytest.raises(TypeError, match="obstacles: expected a list"):
        CFFTG(generator.config).generate_batch(ob)
    with pytest.raises(TypeError, match="config: expected a jaxexo Config"):
        CFFTG(42)
    # the obvious intent: a config file's path, and None for the default model
    assert CFFTG(str(ROOT / "configs" / "quick.toml")).config == load_config(
        ROOT / "configs" / "quick.toml"
    )
    assert CFFTG(None).config == load_config(ROOT / "configs" / "default.toml")


def test_every_size_from_input_is_bounded_before_allocating(generator):
    from jaxexo.inference import Obstacle
    from jaxexo.swing.timing import DeviceLimits, time_swing

    ob = Obstacle.named("base1")
    with pytest.raises(ValueError, match="n_points must be an integer in"):
        generator.generate(ob, n_points=100_000_000)
    with pytest.raises(ValueError, match="duration must be <= 60 s"):
        generator.generate(ob, duration=1e300)
    with pytest.raises(ValueError, match="duration must be > 0 s"):
        generator.generate(ob, duration=-1.0)
    traj = generator.generate(ob)
    with pytest.raises(ValueError, match="rate: control rate must be"):
        time_swing(traj, generator.config, rate=1e9)
    tiny = DeviceLimits((1e-6,) * 4, (1e-6,) * 4)
    with pytest.raises(ValueError, match="samples, more than"):
        time_swing(traj, generator.config, limits=tiny)
    # A minimum duration over a swing's 60 s is refused when the limits are made (the [device]
    # section's bound), before any timing.
    with pytest.raises(ValueError, match=r"limits\.min_duration: .*\[0, 60\]"):
        DeviceLimits((3.0, 4.0, 3.0, 4.0), (15.0, 20.0, 15.0, 20.0), min_duration=1e6)


# --------------------------------------------------------------------------------------------
# Configs: one default, every shipped config unchanged in meaning, physical bounds
# --------------------------------------------------------------------------------------------


def test_an_empty_config_config_and_the_packaged_default_are_one_default(tmp_path):
    from jaxexo.config import Config, load_config, packaged_config

    default = load_config(packaged_config("default"))
    empty = tmp_path / "empty.toml"
    empty.write_text("")
    assert Config() == default == config_from_dict({}) == load_config(empty)
    assert load_config(ROOT / "configs" / "default.toml") == default


def test_the_environment_defaults_to_the_default_model():
    pytest.importorskip("jax")
    from jaxexo.config import Config
    from jaxexo.env import ExoStepEnv

    assert ExoStepEnv().config == Config()


def test_every_shipped_config_resolves_as_it_did_before_the_defaults_changed():
    """tests/data/resolved_configs.json was generated from main before the schema's declared defaults
    became the default model's: every config file (and every sweep member) means what it meant."""
    sys.path.insert(0, str(ROOT / "tests"))
    from resolved_snapshot import REDEFINED, SNAPSHOT, resolved

    snap = json.loads(SNAPSHOT.read_text())
    now = resolved()
    # every config of the snapshot still ships (configs added since had no earlier meaning to keep)
    assert set(snap["configs"]) <= set(now["configs"]) and set(snap["sweeps"]) <= set(now["sweeps"])
    assert REDEFINED <= set(snap["configs"]) | set(snap["sweeps"])
    for name, text in snap["configs"].items():
        if name not in REDEFINED:
            assert now["configs"][name] == text, name
    for name, digests in snap["sweeps"].items():
        if name not in REDEFINED:
            assert now["sweeps"][name] == digests, name


def test_the_tests_legacy_base_is_the_former_schema_defaults():
    """The tests' raw configs are stated on top of conftest.legacy_raw: the former Config()."""
    from jaxexo.config.toml_io import config_to_toml

    from conftest import legacy_raw

    snap = json.loads((ROOT / "tests" / "data" / "resolved_configs.json").read_text())
    from resolved_snapshot import without_added

    assert (
        without_added(config_to_toml(config_from_dict(legacy_raw({})))) == snap["schema_defaults"]
    )


@pytest.mark.parametrize(
    "raw, message",
    [
        ({"env": {"backward_tolerance": 100}}, r"env\.backward_tolerance: must be <= 10"),
        ({"env": {"shield_clearance": 5.0}}, r"env\.shield_clearance: must be <= 0.1"),
        (
            {"env": {"shield_clearance": 0.001}},
            r"env\.shield_clearance: 0.001 m is below env\.min_clearance",
        ),
        ({"kinematics": {"thigh": 1e9}}, r"kinematics\.thigh: must be <= 1.0"),
        ({"kinematics": {"shin": 2.0}}, r"kinematics\.shin: must be <= 1.0"),
        ({"kinematics": {"foot_length": 3.0}}, r"kinematics\.foot_length: must be <= 0.5"),
        (
            {"device": {"joint_velocity": [1e-9, 1e-9]}},
            r"device\.joint_velocity\[0\]: must be >= 0.1",
        ),
        (
            {"device": {"joint_acceleration": [1e9, 20.0]}},
            r"device\.joint_acceleration\[0\]: must be <= 1000",
        ),
        ({"device": {"min_swing_duration": 1e9}}, r"device\.min_swing_duration: must be <= 60"),
        ({"device": {"control_rate": 1e12}}, r"device\.control_rate: must be <= 10000"),
    ],
)
def test_physically_meaningless_settings_are_refused_naming_the_field(raw, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict(raw)


def test_shield_clearance_below_min_clearance_is_accepted_only_without_the_shield():
    cfg = config_from_dict({"env": {"shield": False, "shield_clearance": 0.001}})
    assert cfg.env.shield_clearance == 0.001


def test_sweep_results_and_named_files_never_write_through_a_link(tmp_path):
    from jaxexo.storage.atomic import atomic_write
    from jaxexo.sweep import results as R

    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    out = tmp_path / "sweep"
    out.mkdir()
    (out / R.RESULTS).symlink_to(victim)
    with pytest.raises(SymlinkRefused, match="results.csv is a symbolic link"):
        R.append_rows(out / R.RESULTS, ["a"], [{"a": 1}])
    # an atomic write replaces the link itself (the reproduce tables, sweep best/, figures)
    (out / "reproduce.md").symlink_to(victim)
    atomic_write(out / "reproduce.md", "tables\n")
    assert not (out / "reproduce.md").is_symlink() and victim.read_text() == "precious\n"
