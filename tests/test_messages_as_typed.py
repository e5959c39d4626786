"""Refusals in the user's words (docs/reliability.md, "Messages"): the option as typed
(``--step-length``, not the library's ``step_length``) and the value as given (10000.0001, not
10000); one number syntax for every numeric option (``0_05`` is not 5 m); terrain files named by the
line of the value at fault, a key written twice refused, a 1 mm floor bump and a vertical spike
worded as what they are; a GIF that cannot be written named."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import pytest

from jaxexo.cli import build_parser, main

from conftest import ROOT
from reference_outputs import POLICY

GEN = ("generate", "--method", "cfftg", "--obstacle", "rectangle")
RL = ("generate", "--policy", POLICY, "--obstacle", "rectangle")
CORRIDOR = "0,0\n3,0\n"


def cli_error(capsys, *argv) -> str:
    """The CLI run in this process: exit 2 and its one ``jaxexo: error`` line, returned."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("jaxexo: error:") and len(err.splitlines()) == 1, err
    return err


def walk_error(capsys, tmp_path, *options, terrain: str = CORRIDOR) -> str:
    path = tmp_path / "t.csv"
    path.write_text(terrain)
    out = tmp_path / "w.csv"
    err = cli_error(capsys, "walk", "--method", "cfftg", "--terrain", path, "--out", out, *options)
    assert not out.exists()
    return err


# --------------------------------------------------------------------------------------------
# The option as typed, the value as given
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, message",
    [
        ((*GEN, "--step-length", "-1"), "--step-length must be > 0 metres, got -1"),
        ((*GEN, "--step-length", "0.1"), "--step-length: the goal (0.1 m) must lie beyond"),
        ((*GEN, "--pivot-y", "nan"), "--pivot-y must be finite, got nan"),
        ((*GEN, "--start-y", "inf"), "--start-y must be finite, got inf"),
        ((*GEN, "--start-y", "1"), "at the start (1.2 m: --start-y 1 m and the foot's 0.2 m)"),
        ((*RL, "--smoothing", "-1"), "--smoothing must be >= 0 (m^2), got -1"),
        ((*RL, "--smoothing", "nan"), "--smoothing must be finite, got nan"),
        ((*GEN, "--rate", "10000.0001"), "--rate: control rate must be between 10 and 10000 Hz, "),
        (
            (*GEN, "--duration", "60.000001"),
            "--duration must be <= 60 s (one swing), got 60.000001",
        ),
    ],
)
def test_generate_names_the_option_as_typed_and_the_value_as_given(capsys, tmp_path, argv, message):
    out = tmp_path / "t.csv"
    err = cli_error(capsys, *argv, "--out", out)
    assert message in err, err
    # The option first, never the library's field name; the value never rounded.
    assert err.startswith("jaxexo: error: --") or "obstacle: its near edge" in err, err
    assert not any(f in err for f in ("step_length", "pivot_y", "start_y"))
    if "10000.0001" in argv:
        assert err.endswith("got 10000.0001"), err
    assert not out.exists()


@pytest.mark.parametrize(
    "options, message",
    [
        (("--start-y", "100"), "--start-y: 100.000 m is not on the course"),
        (("--start-y", "2.8004"), "--start-y: 2.8004 m is not on the course"),
        (("--goal-y", "100"), "--goal-y: 100.000 m is beyond the last place"),
        (("--goal-y", "-1"), "--goal-y: -1.000 m must lie ahead of the start"),
        (("--double-support", "1e9"), "--double-support: at most 10 s, got 1e+09"),
        (("--double-support", "10.0000001"), "--double-support: at most 10 s, got 10.0000001"),
        (("--double-support", "-1"), "--double-support: must be a finite number >= 0, got -1"),
    ],
)
def test_walk_names_the_option_as_typed_and_the_value_as_given(capsys, tmp_path, options, message):
    err = walk_error(capsys, tmp_path, *options)
    assert err.startswith(f"jaxexo: error: {message}"), err
    assert not any(f in err for f in ("start_y", "goal_y", "double_support", "got -1.0"))


def test_a_refusal_of_a_field_the_subcommand_has_no_option_for_is_left_as_it_is():
    from jaxexo.cli.common import as_typed

    walk = build_parser().parse_args(["walk", "--terrain", "t", "--out", "o"])
    assert (
        as_typed("start_y: 1 m is not on the course", walk) == "--start-y: 1 m is not on the course"
    )
    # walk has no --step-length; a config key keeps its name.
    assert as_typed("step_length must be > 0", walk) == "step_length must be > 0"
    assert as_typed("layout.start_y: bad", walk) == "layout.start_y: bad"
    train = build_parser().parse_args(["train", "c.toml", "--out", "r"])
    assert as_typed("rate: 5", train) == "rate: 5"


# --------------------------------------------------------------------------------------------
# One number syntax for every numeric option
# --------------------------------------------------------------------------------------------


def _numeric_options():
    """(subcommand, option, type) of every option that parses a number."""
    top = build_parser()
    (sub,) = [a for a in top._actions if isinstance(a, argparse._SubParsersAction)]
    for name, parser in sub.choices.items():
        for action in parser._actions:
            if action.option_strings and action.type is not None and action.type is not str:
                yield name, action.option_strings[-1], action.type


def test_every_numeric_option_reads_numbers_in_the_one_syntax():
    from jaxexo.cli.common import real, whole

    found = list(_numeric_options())
    assert len(found) >= 25, found
    # Python's float() and int() read 0_05 as 5: no option is parsed by them.
    plain = [(c, o) for c, o, t in found if t in (float, int)]
    assert plain == []
    assert {"--start-y", "--step-length", "--goal-y", "--points", "--rate"} <= {
        o for _, o, t in found if t in (real, whole)
    }


@pytest.mark.parametrize(
    "argv, option, text",
    [
        ((*GEN, "--start-y", "0_05"), "--start-y", "0_05"),
        ((*GEN, "--step-length", "0_7"), "--step-length", "0_7"),
        ((*GEN, "--points", "1_00"), "--points", "1_00"),
        ((*GEN, "--rate", "1_000"), "--rate", "1_000"),
        (("walk", "--terrain", "t.csv", "--start-y", "0_05"), "--start-y", "0_05"),
        (("walk", "--terrain", "t.csv", "--steps", "1_0"), "--steps", "1_0"),
        (("train", "c.toml", "--seed", "1_0"), "--seed", "1_0"),
    ],
)
def test_an_underscore_in_a_number_is_refused_naming_the_option_and_the_text(
    capsys, tmp_path, argv, option, text
):
    out = tmp_path / "t.csv"
    with pytest.raises(SystemExit) as stop:
        main([str(a) for a in argv] + ["--out", str(out)])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: '{text}' is not a" in err and "no '_'" in err, err
    assert "Traceback" not in err and not out.exists()


def test_the_one_syntax_still_reads_every_number_it_read():
    from jaxexo.cli.common import real, whole

    for text, value in (("0.05", 0.05), ("-1", -1.0), ("1e3", 1000.0), (".5", 0.5), (" 2 ", 2.0)):
        assert real(text) == value
    assert str(real("nan")) == "nan" and real("-inf") == float("-inf")
    assert whole("42") == 42 and whole("-3") == -3
    for bad in ("0_05", "1,5", "0x10", "", "\uff11"):
        with pytest.raises(argparse.ArgumentTypeError):
            real(bad)
    for bad in ("1_0", "1.0", "1e3"):
        with pytest.raises(argparse.ArgumentTypeError):
            whole(bad)


# --------------------------------------------------------------------------------------------
# Terrain files
# --------------------------------------------------------------------------------------------


def _terrain_error(tmp_path, name: str, text: str) -> str:
    from jaxexo.storage.terrain_file import TerrainFileError, read_terrain

    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(TerrainFileError) as e:
        read_terrain(path)
    assert str(e.value).startswith(f"{path}, ") or str(e.value).startswith(f"{path}:")
    return str(e.value)


def _line_of(text: str, needle: str) -> int:
    """The line (from 1) of the only line of ``text`` holding ``needle``: the reference."""
    (line,) = [k for k, s in enumerate(text.splitlines(), 1) if needle in s]
    return line


@pytest.mark.parametrize(
    "points, needle, index, message",
    [
        ([[0.0, 0.0], [2.0, 0.0], [1.5, 0.0]], "1.5", 2, "y = 1.5 m is behind"),
        ([[0.0, 0.0], [1.0, -0.25], [2.0, 0.0]], "-0.25", 1, "z = -0.25 m is below the floor"),
        ([[0.0, 0.0], [1.0, 0.0], [2.0, "x"]], '"x"', 2, "expected a pair [y, z] of numbers"),
        ([[0.0, 0.0], [1.0, 0.0], [2.0, 5.0]], "5.0", 2, "z = 5 m, higher than a terrain"),
    ],
)
def test_a_pretty_printed_terrain_json_names_the_line_of_the_value_at_fault(
    tmp_path, points, needle, index, message
):
    # json.dump(indent=2), the way a terrain is written from Python, puts each value on its own line.
    text = json.dumps({"points": points}, indent=2)
    err = _terrain_error(tmp_path, "t.json", text)
    assert f", line {_line_of(text, needle)} (points[{index}]): {message}" in err, (err, text)


def test_a_terrain_json_error_counts_lines_as_an_editor_does(tmp_path):
    # Old Mac line ends (CR alone): line 4 is the pair with no comma before it.
    text = '{"points": [\r  [0, 0],\r  [1, 0]\r  [2, 0]\r]}\r'
    err = _terrain_error(tmp_path, "cr.json", text)
    assert ", line 4: not valid JSON" in err, err
    text = '{"points": [\r  [0, 0],\r  [1, -1],\r  [2, 0]\r]}\r'
    assert ", line 3 (points[1]): z = -1 m" in _terrain_error(tmp_path, "cr2.json", text)


def test_a_key_written_twice_in_a_terrain_json_is_refused_naming_it(tmp_path):
    text = '{"points": [[0, 0], [1, 0]],\n "points": [[0, 0], [3, 0]]}\n'
    err = _terrain_error(tmp_path, "dup.json", text)
    assert 'line 2: the key "points" is written twice' in err, err


def test_a_floor_with_millimetre_noise_is_worded_in_millimetres(capsys, tmp_path):
    # The terrain file's rule (docs/walking.md): the floor is z = 0 exactly, anything above it an
    # obstacle. A floor measured with 1 mm of noise is refused as before, but not as "0 cm high".
    rows = [f"{0.05 * i:.2f},{0.001 if i else 0.0}" for i in range(61)]
    err = walk_error(capsys, tmp_path, terrain="\n".join(rows) + "\n")
    assert "(1 mm high; the floor is z = 0 exactly" in err, err
    assert "0 cm high" not in err


def test_a_vertical_spike_names_the_file_and_its_line(capsys, tmp_path):
    terrain = "y,z\n# a spike at 1 m\n0,0\n1.0,0\n1.0,0.1\n1.0,0\n3,0\n"
    err = walk_error(capsys, tmp_path, terrain=terrain)
    assert f"{tmp_path / 't.csv'}, line 5: the obstacle at y = 1.00-1.00 m (10 cm high)" in err
    assert "vertical spike" in err and "(width) must be > 0" not in err


def test_a_vertical_spike_given_as_points_names_the_point():
    from jaxexo.baselines import CFFTG
    from jaxexo.cli.common import load
    from jaxexo.course import CourseError, plan_course

    with pytest.raises(CourseError, match=r"^<terrain>, point 2: .* vertical spike"):
        plan_course(CFFTG(load(None)[0]), [[0, 0], [1.0, 0], [1.0, 0.1], [1.0, 0], [3, 0]])


# --------------------------------------------------------------------------------------------
# A GIF past the file-size limit
# --------------------------------------------------------------------------------------------

# A file-size limit (RLIMIT_FSIZE, as ``ulimit -f``) set in a fresh interpreter that then execs the
# command, SIGXFSZ ignored so a write past it fails with EFBIG (tests/test_reliability.py's way).
_LIMITED = (
    "import os, resource, signal, sys\n"
    "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
    "n = int(sys.argv[1]); resource.setrlimit(resource.RLIMIT_FSIZE, (n, n))\n"
    "os.execv(sys.argv[2], sys.argv[2:])\n"
)


# A swing animated at 2 frames a second: the GIF write of ``jaxexo generate --animate`` and ``walk
# --animate`` (jaxexo.plots.animate) in a few seconds.
_ANIMATE = """
import sys
from jaxexo.baselines import CFFTG
from jaxexo.cli.common import load
from jaxexo.physics.geometry import Obstacle
from jaxexo.plots.animate import animate_swing
from jaxexo.swing.timing import time_swing

config = load(None)[0]
swing = time_swing(CFFTG(config).generate(Obstacle.named("base1")), config)
try:
    animate_swing(swing, sys.argv[1], fps=2.0, hold_s=0.0)
except OSError as e:
    print(e)
    sys.exit(7)
"""


def test_an_animation_past_the_file_size_limit_names_the_gif(tmp_path):
    gif = tmp_path / "swing.gif"
    r = subprocess.run(
        [sys.executable, "-c", _LIMITED, "3000", sys.executable, "-c", _ANIMATE, str(gif)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert r.returncode == 7, r.stderr[-2000:]
    assert r.stdout.strip() == f"[Errno 27] could not write {gif}: File too large"
    assert list(tmp_path.iterdir()) == []  # no GIF, whole or in part
