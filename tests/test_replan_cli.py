"""``jaxexo generate --replan-at T`` (jaxexo.cli.replan): the swing planned as without it, replanned
at T over the new obstacle and written through every output. Checked against a run without the
replan: the CSV's rows before T are that run's, the JSON records the switch, the ROS message has the
CSV's rows; finite differences of the CSV hold the limits across the switch. Every misuse of the
options is refused naming the option as typed, exit 2, nothing written."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from jaxexo.cli import main
from jaxexo.swing.export import TIMED_CSV_COLUMNS

from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
SCENE = ["--obstacle", "rectangle", "--width", "0.10", "--height", "0.06"]
TALLER = ["--replan-obstacle", "rectangle", "--replan-width", "0.10", "--replan-height", "0.10"]
AT = 0.3


def _rows(path) -> np.ndarray:
    rows = list(csv.reader(path.read_text().splitlines()))
    assert tuple(rows[0]) == TIMED_CSV_COLUMNS
    return np.array(rows[1:], dtype=np.float64)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """generate at 100 Hz without and with --replan-at (every output of the replanned swing)."""
    d = tmp_path_factory.mktemp("replan_cli")
    base = ["generate", "--policy", POLICY, *SCENE, "--rate", "100"]
    assert main([*map(str, base), "--out", str(d / "a.csv"), "--json", str(d / "a.json")]) == 0
    files = {k: d / f"b.{k}" for k in ("csv", "json", "png", "gif")}
    files["ros"] = d / "b_ros.json"
    rc = main(
        [
            *map(str, base),
            *TALLER,
            "--replan-at",
            str(AT),
            "--out",
            str(files["csv"]),
            "--json",
            str(files["json"]),
            "--ros",
            str(files["ros"]),
            "--plot",
            str(files["png"]),
            "--animate",
            str(files["gif"]),
        ]
    )
    return d, rc, files


def test_the_replanned_swing_is_the_planned_one_before_the_switch(runs, capsys):
    d, rc, f = runs
    plain, new = _rows(d / "a.csv"), _rows(f["csv"])
    before = plain[:, 0] < AT
    assert before.sum() == 30
    # The same rows up to the switch (time, heel, joints and their rates), to rounding.
    np.testing.assert_allclose(new[: before.sum()], plain[before], rtol=0, atol=1e-12)
    assert np.abs(new[before.sum() :, 11:15] - _at(plain, new[before.sum() :, 0])).max() > 1e-3
    doc, old_doc = json.loads(f["json"].read_text()), json.loads((d / "a.json").read_text())
    assert doc["switch_times_s"] == [AT] and old_doc["switch_times_s"] == []
    assert doc["scene"]["height"] == pytest.approx(0.10) and old_doc["scene"]["height"] == 0.06
    assert doc["piecewise"] is not None
    np.testing.assert_array_equal(np.array(doc["samples"]), new)
    ros = json.loads(f["ros"].read_text())
    assert len(ros["points"]) == len(new)
    np.testing.assert_array_equal([p["positions"] for p in ros["points"]], new[:, 11:15])
    assert f["png"].read_bytes()[:4] == b"\x89PNG" and f["gif"].read_bytes()[:3] == b"GIF"
    # Lands at rest on the floor.
    assert new[-1, 2] == 0.0 and np.abs(new[-1, 15:23]).max() < 1e-9
    assert rc == (0 if doc["checks"]["ok"] else 1)


def _at(rows: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The joint angles of ``rows`` interpolated at times ``t`` (held at the last row after it)."""
    return np.column_stack([np.interp(t, rows[:, 0], rows[:, c]) for c in range(11, 15)])


def test_finite_differences_hold_the_limits_across_the_switch(runs):
    _, _, f = runs
    doc = json.loads(f["json"].read_text())
    if not doc["checks"]["within_limits"]:
        pytest.skip("the replanned swing is not within the limits (its verdict says so)")
    q = _rows(f["csv"])[:, 11:15]
    dt = 1.0 / doc["rate_hz"]
    lim = doc["limits"]
    for n, key in (
        (1, "joint_velocity_rad_s"),
        (2, "joint_acceleration_rad_s2"),
        (3, "joint_jerk_rad_s3"),
    ):
        fd = np.abs(np.diff(q, n=n, axis=0)) / dt**n
        assert np.all(fd <= np.asarray(lim[key]) * (1 + 1e-3)), key


def test_the_report_says_where_it_switched_and_the_verdict(tmp_path, capsys):
    out = tmp_path / "s.csv"
    rc = main(
        [
            "generate",
            "--policy",
            str(POLICY),
            *SCENE,
            *TALLER,
            "--replan-at",
            "0.25",
            "--out",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if x.startswith("replanned at"))
    assert "t = 0.2500 s" in line and "rectangle 10.0 x 10.0 cm" in line
    assert line.endswith(("ok", "FAILED")) and rc == (0 if line.endswith("ok") else 1)
    # Timed at the config's control rate without --rate: one row per 10 ms.
    t = _rows(out)[:, 0]
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-12)


def test_cfftg_replans_too(tmp_path, capsys):
    out, js = tmp_path / "c.csv", tmp_path / "c.json"
    rc = main(
        ["generate", "--method", "cfftg", *SCENE, *TALLER, "--replan-at", "0.3"]
        + ["--out", str(out), "--json", str(js)]
    )
    doc = json.loads(js.read_text())
    assert doc["switch_times_s"] == [0.3] and rc == (0 if doc["checks"]["ok"] else 1)
    assert "replanned at t = 0.3000 s" in capsys.readouterr().out


PROFILE = "y_m,z_m\n0.40,0\n0.40,0.10\n0.50,0.10\n0.50,0\n"

REFUSED = [
    (["--replan-width", "0.1"], "--replan-width: needs --replan-at"),
    (["--replan-obstacle", "base1"], "--replan-obstacle: needs --replan-at"),
    (["--replan-profile", "{profile}"], "--replan-profile: needs --replan-at"),
    (["--replan-at", "0.3"], "--replan-at: give the new obstacle"),
    (["--replan-at", "-1", *TALLER], "--replan-at: expected a time in s after lift-off"),
    (["--replan-at", "0", *TALLER], "--replan-at: expected a time in s after lift-off"),
    (["--replan-at", "nan", *TALLER], "got nan"),
    (["--replan-at", "100", *TALLER], "(0 < t < 60, the longest swing), got 100"),
    (["--replan-at", "5", *TALLER], "--replan-at: expected a time in s within the swing"),
    (
        ["--replan-at", "0.3", "--replan-obstacle", "base1", "--replan-profile", "{profile}"],
        "--replan-obstacle, --replan-profile: give one of them",
    ),
    (
        ["--replan-at", "0.3", "--replan-profile", "{profile}", "--replan-height", "0.1"],
        "--replan-height: not with --replan-profile",
    ),
    (["--replan-at", "0.3", *TALLER[:-1], "5"], "--replan-height: height must be <="),
    (["--replan-at", "0.3", "--replan-profile", "{missing}"], "no such terrain file"),
    # The foot mid-swing inside a tall block over the middle of the step.
    (
        ["--replan-at", "0.5", "--replan-obstacle", "rectangle", "--replan-width", "0.3"]
        + ["--replan-height", "0.5", "--replan-center-y", "0.42"],
        "--replan-obstacle: at t=0.5000 s the foot (heel y=",
    ),
    # ... or only within the margin of one that ends just below the heel.
    (
        ["--replan-at", "0.5", "--replan-obstacle", "rectangle", "--replan-width", "0.3"]
        + ["--replan-height", "0.095", "--replan-center-y", "0.42"],
        "0.02 m: no continuation from there keeps it",
    ),
]


@pytest.mark.parametrize("extra,message", REFUSED)
def test_replan_options_are_refused_by_name_writing_nothing(tmp_path, capsys, extra, message):
    prof = tmp_path / "p.csv"
    prof.write_text(PROFILE)
    extra = [a.format(profile=prof, missing=tmp_path / "none.csv") for a in extra]
    out, js = tmp_path / "s.csv", tmp_path / "s.json"
    rc = main(
        ["generate", "--policy", str(POLICY), *SCENE, *extra, "--out", str(out), "--json", str(js)]
    )
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("jaxexo: error: ") and message in err and "Traceback" not in err
    assert not out.exists() and not js.exists()
