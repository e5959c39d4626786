"""The exports as a real client reads them: the ``--ros`` JSON built into ROS 2
``trajectory_msgs/msg/JointTrajectory`` messages by the ``rosbags`` type store (its layout the
reference), CDR-serialised, written to rosbag2 files and read back bit for bit, with the joints
named as the robot names them; CSVs at full precision (finite differences at 10 kHz hold the
limits); one output file per path whatever its name; and output paths refused before any work.
docs/reliability.md, "Exports", lists these cases."""

from __future__ import annotations

import io
import json
import os
import subprocess

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.cli import main
from jaxexo.inference import Obstacle
from jaxexo.swing.export import JOINT_NAMES
from jaxexo.swing.timing import time_swing

from conftest import ROOT, cli_cmd

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
GEN = ("generate", "--policy", str(POLICY), "--method", "cfftg", "--obstacle", "triangle")
JT = "trajectory_msgs/msg/JointTrajectory"
ROBOT = ["l_hip", "l_knee", "r_hip", "r_knee"]


@pytest.fixture(scope="module")
def cfftg_swing():
    """One CFFTG swing over the triangle, timed at 100 Hz, and its generator's config."""
    cf = CFFTG.from_policy(POLICY)
    traj = cf.generate(Obstacle.named("triangle"))
    return time_swing(traj, cf.config, rate=100.0), cf.config


def _bits(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64).view(np.uint64)


def _refused(capsys, argv, *needles) -> str:
    """``jaxexo ARGV`` in this process: exit 2, one ``jaxexo: error`` line naming the needles."""
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith("jaxexo: error:") and len(err.strip().splitlines()) == 1, err
    for n in needles:
        assert n in err, (n, err)
    return err


# --------------------------------------------------------------------------------------------
# ROS 2: real JointTrajectory messages from the --ros JSON (rosbags type store, CDR, rosbag2)
# --------------------------------------------------------------------------------------------


def _message(store, msgtype: str, doc):
    """``doc`` (the JSON) as a ``msgtype`` message of ``store``, strictly: every field of the
    layout present in its order and nothing else, each of its declared type (a strict conversion,
    as a bridge from JSON does)."""
    _, fields = store.fielddefs[msgtype]
    assert isinstance(doc, dict) and list(doc) == [n for n, _ in fields], (msgtype, doc)
    return store.types[msgtype](**{n: _field(store, desc, doc[n]) for n, desc in fields})


def _field(store, desc, value):
    from rosbags.interfaces import Nodetype

    kind, arg = desc
    if kind == Nodetype.NAME:
        return _message(store, arg, value)
    if kind == Nodetype.SEQUENCE:
        (sub_kind, sub_arg), _ = arg
        assert isinstance(value, list)
        if sub_kind == Nodetype.BASE and sub_arg[0] == "float64":
            assert all(type(x) is float for x in value), value
            return np.array(value, dtype=np.float64)
        return [_field(store, (sub_kind, sub_arg), x) for x in value]
    assert kind == Nodetype.BASE, desc
    bounds = {"int32": (-(2**31), 2**31), "uint32": (0, 2**32)}
    if arg[0] == "string":
        assert type(value) is str
    elif arg[0] in bounds:
        lo, hi = bounds[arg[0]]
        assert type(value) is int and lo <= value < hi, (arg, value)
    else:
        raise AssertionError(f"a field of type {arg[0]} in the layout: extend this converter")
    return value


def _check_message(msg, swing, names) -> None:
    """A deserialised message against the swing itself, bit for bit."""
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (0, 0)
    assert msg.header.frame_id == "" and list(msg.joint_names) == list(names)
    assert len(msg.points) == len(swing.time)
    for i, p in enumerate(msg.points):
        for got, want in (
            (p.positions, swing.joint_angles[i]),
            (p.velocities, swing.joint_velocity[i]),
            (p.accelerations, swing.joint_acceleration[i]),
        ):
            assert got.dtype == np.float64 and np.array_equal(_bits(got), _bits(want))
        assert len(p.effort) == 0
        ns = p.time_from_start.sec * 1_000_000_000 + p.time_from_start.nanosec
        assert ns == round(float(swing.time[i]) * 1e9) and p.time_from_start.nanosec < 10**9


@pytest.mark.parametrize("names", [None, ROBOT])
def test_the_ros_json_is_a_joint_trajectory_message_that_round_trips_through_cdr(
    cfftg_swing, tmp_path, names
):
    """The type store's JointTrajectory (ROS 2 Humble) built strictly from the JSON: every field
    there (header.stamp included: 0 = start now), none extra, each of its type; CDR-serialised and
    read back, positions, velocities, accelerations, times, names and stamp are the swing's bits."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    swing, _ = cfftg_swing
    doc = json.loads(swing.to_joint_trajectory(tmp_path / "ros.json", joint_names=names))
    assert doc["header"]["stamp"] == {"sec": 0, "nanosec": 0}
    msg = _message(store, JT, doc)
    raw = store.serialize_cdr(msg, JT)
    back = store.deserialize_cdr(raw, JT)
    _check_message(back, swing, JOINT_NAMES if names is None else names)
    assert bytes(store.serialize_cdr(back, JT)) == bytes(raw)


def test_generate_joint_names_reach_a_rosbag2_file_bit_for_bit(tmp_path, capsys):
    """`jaxexo generate --ros F --joint-names ...`: F's message written to rosbag2 files (sqlite3
    and MCAP) by rosbags' writer and read back by its reader is the swing, under the robot's
    joint names."""
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    ros, js = tmp_path / "ros.json", tmp_path / "s.json"
    argv = [*GEN, "--rate", "100", "--out", tmp_path / "s.csv", "--json", js, "--ros", ros]
    rc = main([str(a) for a in argv] + ["--joint-names", " l_hip, l_knee,r_hip,r_knee"])
    assert rc == 0, capsys.readouterr().err
    doc = json.loads(ros.read_text())
    samples = np.asarray(json.loads(js.read_text())["samples"])
    swing = type("Swing", (), {})()  # the samples the same run wrote to its JSON
    swing.time, swing.joint_angles = samples[:, 0], samples[:, 11:15]
    swing.joint_velocity, swing.joint_acceleration = samples[:, 15:19], samples[:, 19:23]
    raw = store.serialize_cdr(_message(store, JT, doc), JT)
    for plugin in (StoragePlugin.SQLITE3, StoragePlugin.MCAP):
        bag = tmp_path / f"bag_{plugin.name}"
        with Writer(bag, version=9, storage_plugin=plugin) as w:
            conn = w.add_connection("/joint_trajectory", JT, typestore=store)
            w.write(conn, 1, raw)
        with Reader(bag) as r:
            got = list(r.messages())
        assert len(got) == 1 and bytes(got[0][2]) == bytes(raw)
        _check_message(store.deserialize_cdr(got[0][2], JT), swing, ROBOT)


@pytest.mark.parametrize(
    "names, needle",
    [
        ("a,b,c", "got 3: 'a,b,c'"),
        ("a,b,c,d,e", "got 5"),
        ("a,b,,d", "name 3 ('')"),
        ("a,b,c,a", "'a' is given twice"),
        ("a,b,c,1d", "name 4 ('1d') is not a ROS name"),
        ("a,b,c,d e", "name 4 ('d e')"),
        ("a,b//c,c,d", "name 2"),
    ],
)
def test_joint_names_are_checked_before_any_work(tmp_path, capsys, names, needle):
    out = tmp_path / "s.csv"
    argv = [*GEN, "--rate", "100", "--out", out, "--ros", tmp_path / "r.json"]
    _refused(capsys, argv + ["--joint-names", names], "--joint-names", needle)
    assert list(tmp_path.iterdir()) == []


def test_joint_names_without_ros_is_refused(tmp_path, capsys):
    _refused(capsys, [*GEN, "--out", tmp_path / "s.csv", "--joint-names", ",".join(ROBOT)], "--ros")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "names, needle",
    [
        ("a,b,c,d", "expected a list"),
        (["a", "b", "c"], "got 3"),
        (["a", "b", "c", 4], "name 4 (4)"),
        (["a", "b", "a", "c"], "'a' is given twice"),
        (["a", "b", "c", "/d/"], "name 4"),
    ],
)
def test_joint_names_in_the_api_are_checked_before_writing(cfftg_swing, tmp_path, names, needle):
    swing, _ = cfftg_swing
    with pytest.raises(ValueError, match="joint_names: ") as e:
        swing.to_joint_trajectory(tmp_path / "r.json", joint_names=names)
    assert needle in str(e.value)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------------------------
# CSVs at full precision: finite differences at 10 kHz hold the limits
# --------------------------------------------------------------------------------------------


def _finite_difference_ratios(q: np.ndarray, rate: float, acc, jerk):
    """The largest |second| and |third| differences of positions q (n, 4) over the limits."""
    a = np.abs(np.diff(q, 2, axis=0)).max(axis=0) * rate**2
    j = np.abs(np.diff(q, 3, axis=0)).max(axis=0) * rate**3
    return a / np.asarray(acc), j / np.asarray(jerk)


def test_a_10khz_generate_csv_round_trips_and_its_finite_differences_hold_the_limits(
    tmp_path, capsys
):
    """`generate --rate 10000`: the CSV read back is the JSON's samples bit for bit, and finite
    differences of its joint angles give acceleration and jerk within the [device] limits less the
    tracking headroom (9 significant digits gave 15x the jerk limit on this swing)."""
    out, js = tmp_path / "s.csv", tmp_path / "s.json"
    assert main([*GEN, "--rate", "10000", "--out", str(out), "--json", str(js)]) == 0
    capsys.readouterr()
    doc = json.loads(js.read_text())
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape[0] > 10_000
    assert np.array_equal(_bits(data), _bits(doc["samples"]))
    lim = doc["limits"]
    scale = 1.0 - lim["tracking_headroom"]
    acc, jerk = _finite_difference_ratios(
        data[:, 11:15], 10_000.0, lim["joint_acceleration_rad_s2"], lim["joint_jerk_rad_s3"]
    )
    assert acc.max() <= scale * (1 + 1e-6) and jerk.max() <= scale * (1 + 1e-5), (acc, jerk)
    # The same samples at 9 digits (the old CSV) break the jerk limit: the check can fail.
    nine = np.vectorize(lambda x: float(f"{x:.9g}"))(data[:, 11:15])
    old = _finite_difference_ratios(
        nine, 10_000.0, lim["joint_acceleration_rad_s2"], lim["joint_jerk_rad_s3"]
    )
    assert old[1].max() > 5.0


def test_a_10khz_walk_csv_round_trips_and_its_finite_differences_hold_the_limits(tmp_path, capsys):
    """`walk --rate 10000` over one block: the CSV is the JSON's samples bit for bit, and finite
    differences of both legs' joint angles across the whole walk (hand-overs included) hold the
    limits less the headroom."""
    from jaxexo.course.record import WALK_COLUMNS

    terrain = tmp_path / "t.csv"
    terrain.write_text("0,0\n0.5,0\n0.55,0.1\n0.65,0.1\n0.7,0\n1.4,0\n")
    out, js = tmp_path / "w.csv", tmp_path / "w.json"
    argv = ["walk", "--method", "cfftg", "--terrain", terrain, "--rate", "10000"]
    assert main([str(a) for a in argv] + ["--out", str(out), "--json", str(js)]) == 0
    capsys.readouterr()
    doc = json.loads(js.read_text())
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert np.array_equal(_bits(data), _bits(doc["samples"]))
    lim = doc["limits"]
    q0 = WALK_COLUMNS.index("hip_left_rad")
    side = [0, 1, 0, 1]  # hip_left, knee_left, hip_right, knee_right: a hip's limits, a knee's
    acc, jerk = _finite_difference_ratios(
        data[:, q0 : q0 + 4],
        10_000.0,
        np.asarray(lim["joint_acceleration_rad_s2"])[side],
        np.asarray(lim["joint_jerk_rad_s3"])[side],
    )
    scale = 1.0 - lim["tracking_headroom"]
    assert acc.max() <= scale * (1 + 1e-6) and jerk.max() <= scale * (1 + 1e-5), (acc, jerk)


def test_csv_numbers_are_the_shortest_round_trip_text():
    from jaxexo.swing.export import csv_number

    for x in (0.1, 1.0, -0.0, 1e-300, 2.0**-1074, 12345.678901234567, np.pi, 1e16):
        assert float(csv_number(x)) == x and np.signbit(float(csv_number(x))) == np.signbit(x)
    assert csv_number(3.0) == "3" and csv_number(0.1) == "0.1" and csv_number(-0.0) == "-0"


# --------------------------------------------------------------------------------------------
# One output file per path, whatever its name (- is standard output)
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--rate", "100", "--out", "-", "--ros", "/dev/stdout"], ["--ros", "--out -"]),
        (["--out", "/dev/stdout", "--json", "-"], ["--json", "--out /dev/stdout"]),
        (["--rate", "100", "--out", "x.csv", "--json", "/dev/stdout", "--ros", "-"], ["--ros"]),
    ],
)
def test_standard_output_under_two_names_is_refused(tmp_path, args, needles):
    """`> f` with two outputs on f (``-`` and /dev/stdout): refused before any work, naming both
    options; f stays empty (one output truncated the other and the run exited 0)."""
    f = tmp_path / "f"
    with open(f, "wb") as stdout:
        r = subprocess.run(
            cli_cmd(*GEN, *args),
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            cwd=tmp_path,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
            timeout=120,
        )
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("jaxexo: error:") and "own path" in r.stderr, r.stderr
    for n in needles:
        assert n in r.stderr, (n, r.stderr)
    assert f.read_bytes() == b"" and sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_walk_refuses_standard_output_under_two_names(tmp_path):
    f = tmp_path / "f"
    terrain = tmp_path / "t.csv"
    terrain.write_text("0,0\n2,0\n")
    with open(f, "wb") as stdout:
        r = subprocess.run(
            cli_cmd("walk", "--method", "cfftg", "--terrain", terrain, "--out", "-")
            + ["--json", "/dev/stdout"],
            stdout=stdout,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
            timeout=120,
        )
    assert r.returncode == 2 and "--json: /dev/stdout is also the --out output" in r.stderr
    assert f.read_bytes() == b""


def test_distinct_outputs_beside_standard_output_still_work(tmp_path, capsys):
    """Only one file under two names is refused: ``-`` beside a file is two outputs."""
    from jaxexo.cli.common import check_paths

    check_paths([], [("--out", "-"), ("--json", tmp_path / "s.json")])
    check_paths([], [("--out", tmp_path / "a.csv"), ("--json", tmp_path / "a.json")])
    with pytest.raises(ValueError, match="--json: - is also the --out output; give"):
        check_paths([], [("--out", "-"), ("--json", "-")])


# --------------------------------------------------------------------------------------------
# Output paths refused before any work: --ros a folder, empty, a link to a folder, no write access
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["folder", "empty", "link to a folder"])
def test_ros_onto_a_folder_or_empty_is_a_clean_refusal(tmp_path, capsys, kind):
    folder = tmp_path / "adir"
    folder.mkdir()
    (tmp_path / "alink").symlink_to(folder)
    value = {"folder": folder, "empty": "", "link to a folder": tmp_path / "alink"}[kind]
    out = tmp_path / "s.csv"
    err = _refused(capsys, [*GEN, "--rate", "100", "--out", out, "--ros", value], "--ros: ")
    assert ("trajectory_ros.json" in err) and not out.exists()
    assert (tmp_path / "alink").is_symlink() and list(folder.iterdir()) == []


def _locked(tmp_path):
    """A folder this process cannot write: /proc/self for root (which writes through any mode),
    else a folder of mode 0555."""
    if os.geteuid() == 0:
        return "/proc/self"
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    return str(locked)


@pytest.mark.parametrize("option", ["--ros", "--json", "--plot"])
def test_an_output_into_a_folder_that_cannot_be_written_is_refused_before_any_work(
    tmp_path, capsys, option
):
    """Refused naming the option and the folder, before the CSV is written (the --ros JSON once
    failed after the work, naming a hidden temporary file)."""
    folder = _locked(tmp_path)
    out = tmp_path / "s.csv"
    target = f"{folder}/x.{'png' if option == '--plot' else 'json'}"
    argv = [*GEN, "--rate", "100", "--out", out, option, target]
    err = _refused(capsys, argv, f"{option}: the folder {folder} cannot be written")
    assert ".tmp" not in err and not out.exists()


def test_walk_checks_its_output_folders_before_reading_the_terrain(tmp_path, capsys):
    folder = _locked(tmp_path)
    out = tmp_path / "w.csv"
    argv = ["walk", "--method", "cfftg", "--terrain", tmp_path / "none.csv", "--out", out]
    _refused(capsys, argv + ["--json", f"{folder}/w.json"], "--json: the folder")
    assert not out.exists()


def test_writing_onto_a_folder_names_the_path_given(cfftg_swing, tmp_path, monkeypatch):
    """to_joint_trajectory("adir") (and any export) names "adir", not a temporary file; a link to
    a folder is refused the same way and stays a link."""
    swing, _ = cfftg_swing
    monkeypatch.chdir(tmp_path)
    (tmp_path / "adir").mkdir()
    (tmp_path / "alink").symlink_to(tmp_path / "adir")
    for name in ("adir", "alink"):
        for write in (swing.to_joint_trajectory, swing.to_csv, swing.to_json):
            with pytest.raises(IsADirectoryError) as e:
                write(name)
            assert f"could not write {name}" in str(e.value) and ".tmp" not in str(e.value)
    assert (tmp_path / "alink").is_symlink() and sorted(os.listdir(tmp_path)) == ["adir", "alink"]


def test_writing_where_no_file_can_be_made_names_the_path_given(cfftg_swing):
    """A folder that takes no new file (/proc/self): the message names the path asked for."""
    swing, _ = cfftg_swing
    with pytest.raises(OSError) as e:
        swing.to_joint_trajectory("/proc/self/x.json")
    assert "could not write /proc/self/x.json" in str(e.value) and ".tmp" not in str(e.value)


@pytest.mark.parametrize("value", ["adir", ""])
def test_mjcf_suggests_an_xml_name(tmp_path, capsys, value):
    (tmp_path / "adir").mkdir()
    path = str(tmp_path / value) if value else ""
    err = _refused(capsys, ["mjcf", "--out", path], "--out")
    assert ".xml" in err and ".csv" not in err


def test_the_test_extra_declares_rosbags():
    import tomllib

    test = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert any(r.startswith("rosbags") for r in test["optional-dependencies"]["test"])


def test_the_ros_json_needs_no_other_reader(cfftg_swing):
    """The JSON is plain: a client with json alone sees the stamp and the names."""
    swing, _ = cfftg_swing
    doc = json.load(io.StringIO(swing.to_joint_trajectory(joint_names=ROBOT)))
    assert doc["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}
    assert doc["joint_names"] == ROBOT
