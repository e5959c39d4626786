"""Options and inputs that used to be taken silently: replay's drive options without ``--driven``
(ignored), ``--reference-rate`` without a sampled ``--reference`` (named by the library's fields), and
a config whose legs differ from the policy's or the swing's ("did not reach the goal" instead of the
kinematics). docs/reliability.md, "Runs and replays". The refusals come before any simulation."""

from __future__ import annotations

import dataclasses

import pytest

from jaxexo.config import load_config
from jaxexo.physics.geometry import Obstacle

from conftest import ROOT, run_cli
from test_reliability_inputs import make_policy


@pytest.fixture(scope="module")
def policy(tmp_path_factory):
    return make_policy(tmp_path_factory.mktemp("policy") / "policy.npz")


def assert_refused(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "jaxexo: error:" in r.stderr, r.stderr[-2000:]
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    for n in needles:
        assert n in r.stderr, (n, r.stderr)


@pytest.mark.parametrize(
    "options",
    [
        ["--reference", "quintic"],
        ["--reference", "curve"],  # the default's own value, typed: still only for --driven
        ["--reference-rate", "250"],
        ["--half-limits"],
        ["--controller", "servo"],
        ["--controller", "pd_ff"],
    ],
)
def test_replay_refuses_drive_options_without_driven(tmp_path, policy, options):
    out = tmp_path / "r.json"
    r = run_cli("replay", "--policy", policy, "--obstacle", "base1", "--json", out, *options)
    assert_refused(r, f"jaxexo: error: {options[0]}: needs --driven", "add --driven")
    assert not out.exists()


@pytest.mark.parametrize(
    "reference, said",
    [
        ([], "--reference was not given (its default, curve,"),
        (["--reference", "curve"], "--reference is curve"),
    ],
)
def test_replay_names_reference_rate_and_reference_as_typed(tmp_path, policy, reference, said):
    r = run_cli("replay", "--policy", policy, "--obstacle", "base1", "--driven",
                "--reference-rate", "2.5e2", *reference)  # fmt: skip
    assert_refused(
        r,
        "--reference-rate: only for a sampled --reference (quintic, cubic or linear)",
        said,
        "got --reference-rate 2.5e2",
    )
    assert "reference_rate" not in r.stderr and "reference=" not in r.stderr


def test_replay_still_drives_with_the_defaults_and_a_sampled_reference(tmp_path, policy):
    """The options given with --driven reach the driven replay; not given, its defaults."""
    import json

    pytest.importorskip("mujoco")
    for extra, controller, reference, rate in (
        ([], "pd_ff", "curve", None),
        (["--controller", "servo", "--reference", "cubic", "--reference-rate", "50"],
         "servo", "cubic", 50.0),
    ):  # fmt: skip
        out = tmp_path / "r.json"
        r = run_cli("replay", "--policy", policy, "--obstacle", "base1", "--method", "cfftg",
                    "--driven", "--json", out, *extra)  # fmt: skip
        assert r.returncode in (0, 1), r.stderr[-2000:]
        driven = json.loads(out.read_text())["replays"]["cfftg"]["driven"]
        assert (driven["controller"], driven["reference"]) == (controller, reference)
        assert driven["reference_rate_hz"] == rate


# --------------------------------------------------------------------------------------------
# A config whose legs differ from the policy's, or from the swing's
# --------------------------------------------------------------------------------------------


def with_legs(cfg, **legs):
    return dataclasses.replace(cfg, kinematics=dataclasses.replace(cfg.kinematics, **legs))


@pytest.mark.parametrize(
    "legs, needles",
    [
        ({"thigh": 0.45}, ["config: kinematics.thigh = 0.45 m", "trained with kinematics.thigh = 0.5 m"]),
        ({"shin": 0.55, "foot_length": 0.25},
         ["config: kinematics.shin = 0.55 m, kinematics.foot_length = 0.25 m",
          "trained with kinematics.shin = 0.5 m, kinematics.foot_length = 0.2 m"]),
    ],
)  # fmt: skip
def test_a_generator_refuses_a_config_with_other_legs_than_its_policy(policy, legs, needles):
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.storage.policy_check import load_checked

    pol, cfg = load_checked(policy)
    TrajectoryGenerator(pol, cfg, str(policy))  # its own config, or one with other fields: fine
    TrajectoryGenerator(pol, dataclasses.replace(cfg, device=cfg.device), str(policy))
    with pytest.raises(ValueError) as e:
        TrajectoryGenerator(pol, with_legs(cfg, **legs), str(policy))
    for n in needles:
        assert n in str(e.value), str(e.value)
    assert str(policy) in str(e.value)


def test_a_swing_is_timed_only_with_the_legs_it_was_made_for():
    from jaxexo.baselines import CFFTG
    from jaxexo.swing.timing import time_swing, time_swings

    cfg = load_config(ROOT / "configs" / "default.toml")
    traj = CFFTG(cfg).generate(Obstacle.named("base1"))
    assert time_swing(traj, cfg).ok
    with pytest.raises(ValueError, match=r"config: kinematics.thigh = 0.45 m, but trajs\[0\] was "
                       r"made for legs with kinematics.thigh = 0.5 m"):  # fmt: skip
        time_swing(traj, with_legs(cfg, thigh=0.45))
    with pytest.raises(ValueError, match=r"kinematics.foot_length = 0.3 m, but trajs\[1\] was "
                       r"made for legs with kinematics.foot_length = 0.2 m"):  # fmt: skip
        time_swings([CFFTG(with_legs(cfg, foot_length=0.3)).generate(Obstacle.named("base1")),
                     traj], with_legs(cfg, foot_length=0.3))  # fmt: skip
