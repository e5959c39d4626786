"""A walk over a course (jaxexo.course, jaxexo.storage.terrain_file, ``jaxexo walk``,
``jaxexo generate --profile``): every bad terrain file and option refused by name (the line, the
position along the course); footholds on flat ground, checked here against the terrain itself;
the walk's exported samples continuous and within the device limits by finite differences of the
samples alone; a refused course writes nothing."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.cli import main
from jaxexo.config import Config
from jaxexo.course import WALK_COLUMNS, CourseError, FootholdRules
from jaxexo.inference import Terrain, footholds, plan_course, read_terrain
from jaxexo.storage import terrain_file
from jaxexo.storage.terrain_file import TerrainFileError

CFG = Config()
FOOT = CFG.kinematics.foot_length
# One 10 cm block: both legs cross it, then both feet stand together beyond it.
BLOCK = [[0.0, 0.0], [0.5, 0.0], [0.55, 0.1], [0.65, 0.1], [0.7, 0.0], [1.4, 0.0]]


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------------------------
# Terrain files
# --------------------------------------------------------------------------------------------

BAD_FILES = [
    ("t.csv", "y_m,z_m\n0,0\n1,0\n0.5,0\n2,0\n", "line 4", "behind"),
    ("t.csv", "0,0\n1,nan\n2,0\n", "line 2", "finite"),
    ("t.csv", "0,0\n1,-0.01\n2,0\n", "line 2", "below the floor"),
    ("t.csv", "0,0\n", "1 point", "at least 2"),
    ("t.csv", "0,0\n1,0\n500,0\n", "line 3", "long"),
    ("t.csv", "0,0\n1,abc\n", "line 2", "not a number"),
    ("t.csv", "0,0\n1,0,3\n", "line 2", "two numbers"),
    ("t.csv", "0,0\n1,5\n", "line 2", "higher"),
    ("t.csv", "# nothing\n", "0 points", "at least 2"),
    ("t.csv", "0,0\n0,0\n", "no length", "no length"),
    ("t.json", '{"points": [[0, 0],\n [1, NaN],\n [2, 0]]}', "line 2", "finite"),
    ("t.json", '{"points": [[0, 0],\n [1, 0],\n [0.5, 0]]}', "line 3", "behind"),
    ("t.json", '{"points": [[0, 0],\n [1, "x"]]}', "line 2", "pair"),
    ("t.json", '{"points": [[0, 0],\n [1, 0]\n', "line 3", "not valid JSON"),
    ("t.json", '{"pts": []}', "t.json", "points"),
    ("t.json", "[[0, 0], [1, -1]]", "points[1]", "below the floor"),
]


@pytest.mark.parametrize("name,text,where,what", BAD_FILES)
def test_a_bad_terrain_file_is_refused_naming_the_line(tmp_path, name, text, where, what):
    p = _write(tmp_path, name, text)
    with pytest.raises(TerrainFileError) as e:
        read_terrain(p)
    assert str(p) in str(e.value) and where in str(e.value) and what in str(e.value)


def test_too_many_points_and_odd_files_are_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(terrain_file, "MAX_POINTS", 3)
    p = _write(tmp_path, "t.csv", "0,0\n1,0\n2,0\n3,0\n")
    with pytest.raises(TerrainFileError, match="line 4: more than 3 points"):
        read_terrain(p)
    with pytest.raises(TerrainFileError, match="not a regular file"):
        read_terrain(tmp_path)
    (tmp_path / "b.csv").write_bytes(b"0,0\n1,\xff\n")
    with pytest.raises(TerrainFileError, match="line 2: not UTF-8"):
        read_terrain(tmp_path / "b.csv")
    with pytest.raises(TerrainFileError, match="cannot read"):
        read_terrain(tmp_path / "missing.csv")


def test_csv_and_json_read_the_same_profile(tmp_path):
    a = read_terrain(
        _write(tmp_path, "t.csv", "# a course\ny_m,z_m\n\n0,0\n0.5,0\n0.5,0.1\n0.7,0\n")
    )
    b = read_terrain(
        _write(tmp_path, "t.json", json.dumps({"points": [[0, 0], [0.5, 0], [0.5, 0.1], [0.7, 0]]}))
    )
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.points, [[0, 0], [0.5, 0], [0.5, 0.1], [0.7, 0]])
    with pytest.raises(TerrainFileError, match="point 1: y = -1"):
        Terrain.from_points([[0, 0], [-1, 0]])


# --------------------------------------------------------------------------------------------
# Footholds
# --------------------------------------------------------------------------------------------


def _flat_around(ter: Terrain, y0: float, y1: float) -> bool:
    """The terrain is at the floor everywhere on [y0, y1] (its own points and its polyline between),
    read from the points alone."""
    ys = np.concatenate([np.linspace(y0, y1, 200), ter.y[(ter.y >= y0) & (ter.y <= y1)]])
    return bool(np.all(np.interp(ys, ter.y, ter.z) == 0.0))


def test_footholds_on_a_flat_corridor_take_nominal_steps():
    ter = Terrain.from_points([[0.0, 0.0], [6.0, 0.0]])
    fh = footholds(ter, CFG)
    r = FootholdRules.of(CFG)
    lengths = [fh.swing(k)[2] - fh.swing(k)[0] for k in range(len(fh))]
    assert all(r.lo - 1e-9 <= s <= r.hi + 1e-9 for s in lengths)
    assert fh.landings[-1] == fh.landings[-2]  # both feet together at the end
    assert fh.landings[-1] >= 6.0 - FOOT - r.tolerance - r.hi / 2
    # The steady swings (after two to start and before two to stop): near the nominal length, the
    # pivot in the middle.
    mid = [fh.swing(k) for k in range(3, len(fh) - 3)]
    assert len(mid) >= 8
    assert all(
        abs((c - a) - r.nominal) <= 0.055 and abs(b - 0.5 * (a + c)) <= 0.02 for a, b, c in mid
    )


def test_footholds_stand_on_flat_ground_clear_of_every_obstacle():
    ter = Terrain.from_points(
        [
            [0, 0],
            [1.0, 0],
            [1.05, 0.12],
            [1.15, 0.12],
            [1.2, 0],
            [2.2, 0],
            [2.3, 0.06],
            [2.4, 0],
            [3.4, 0],
            [3.4, 0.04],
            [3.7, 0.04],
            [3.7, 0],
            [4.6, 0],
        ]
    )
    fh = footholds(ter, CFG)
    r = FootholdRules.of(CFG)
    for y in fh.landings:
        assert _flat_around(ter, y - r.tolerance - 0.02, y + FOOT + r.tolerance + 0.02), y
    assert fh.landings[-1] > 3.7  # past the last obstacle


@pytest.mark.parametrize(
    "points,kw,message",
    [
        # a block wider than the longest swing can span
        (
            [[0, 0], [0.5, 0], [0.5, 0.05], [1.2, 0.05], [1.2, 0], [2.5, 0]],
            {},
            "no step can cross the obstacle at y = 0.50-1.20 m",
        ),
        # a wall no heel reaches over
        (
            [[0, 0], [0.6, 0], [0.6, 0.9], [0.7, 0.9], [0.7, 0], [2.0, 0]],
            {},
            "no swing can clear the obstacle at y = 0.60-0.70 m",
        ),
        # bumps closer together than a foot: no flat foothold within a step
        (
            [[0, 0], [0.5, 0]]
            + [[0.5 + 0.2 * i + d, z] for i in range(8) for d, z in ((0.05, 0.05), (0.15, 0.0))]
            + [[2.5, 0]],
            {},
            "no further than y = 0.00 m: .* across the obstacle at y = 0.50-0.65 m",
        ),
        (BLOCK, {"start_y": 0.45}, "start_y: the feet at y = 0.450 m do not stand on flat ground"),
        (BLOCK, {"goal_y": 0.6}, "goal_y: a foot at y = 0.600 m does not stand on flat ground"),
        (BLOCK, {"goal_y": 3.0}, "goal_y: 3.000 m is beyond"),
        (BLOCK, {"goal_y": -1.0}, "must lie ahead of the start"),
        (BLOCK, {"goal_y": 1.0, "steps": 2}, "give one of them"),
        (BLOCK, {"steps": 0}, "steps: must be a finite number >= 1"),
        (BLOCK, {"steps": 1.5}, "steps: expected a whole number"),
        (BLOCK, {"steps": True}, "steps: expected a number"),
        (BLOCK, {"start_y": float("nan")}, "start_y: must be a finite number"),
        (
            [[0, 0], [1.0, 0], [1.1, 0.1], [1.2, 0]],
            {},
            "no flat ground|no walk gets past the obstacle at y = 1.00-1.20 m",
        ),
    ],
)
def test_infeasible_courses_and_bad_options_are_refused_naming_where(points, kw, message):
    with pytest.raises(CourseError, match=message):
        footholds(Terrain.from_points(points), CFG, **kw)


def test_a_fixed_number_of_steps():
    fh = footholds(Terrain.from_points([[0, 0], [3, 0]]), CFG, steps=4)
    assert len(fh) == 4 and fh.landings[-1] == fh.landings[-2]
    with pytest.raises(CourseError, match="no walk of 4 swings"):
        footholds(Terrain.from_points(BLOCK), CFG, steps=4)


# --------------------------------------------------------------------------------------------
# Walks
# --------------------------------------------------------------------------------------------


def _check_walk_samples(table: np.ndarray, rate: float, limits) -> None:
    """Independent of the planner: uniform time at the control rate, joint angles continuous, and
    finite differences of the exported angles within the velocity, acceleration and jerk limits."""
    t = table[:, 0]
    dt = 1.0 / rate
    np.testing.assert_allclose(np.diff(t), dt, atol=1e-6)
    q = table[
        :,
        [
            WALK_COLUMNS.index(f"{j}_rad")
            for j in ("hip_left", "knee_left", "hip_right", "knee_right")
        ],
    ]
    v = np.diff(q, axis=0) / dt
    a = np.diff(q, n=2, axis=0) / dt**2
    assert np.all(np.abs(v) <= np.asarray(limits.velocity) * (1 + 1e-3))
    assert np.all(np.abs(a) <= np.asarray(limits.acceleration) * (1 + 1e-3))
    # Jerk too, across the hand-overs: each swing is a curve at rest with zero acceleration at both
    # ends, so the walk is as continuous at a hand-over as inside a swing.
    j = np.diff(q, n=3, axis=0) / dt**3
    assert np.all(np.abs(j) <= np.asarray(limits.jerk) * (1 + 1e-3))
    # Both legs at rest at the start and at the end.
    np.testing.assert_allclose(table[0, WALK_COLUMNS.index("hip_left_vel_rad_s") :], 0.0, atol=1e-9)
    np.testing.assert_allclose(
        table[-1, WALK_COLUMNS.index("hip_left_vel_rad_s") :], 0.0, atol=1e-9
    )


def test_a_cfftg_walk_is_continuous_within_the_limits_and_lands_on_flat_ground(tmp_path):
    ter = Terrain.from_points(BLOCK)
    course = plan_course(CFFTG(CFG), ter, rate=50)
    assert course.ok, course.reasons
    _check_walk_samples(course.samples, 50.0, course.limits)
    # The CSV holds the same samples (written at full precision).
    text = course.to_csv(tmp_path / "w.csv")
    rows = list(csv.reader(text.splitlines()))
    assert tuple(rows[0]) == WALK_COLUMNS
    np.testing.assert_allclose(np.array(rows[1:], float), course.samples, rtol=1e-8, atol=1e-9)
    r = FootholdRules.of(CFG)
    hl, hr = WALK_COLUMNS.index("left_heel_y_m"), WALK_COLUMNS.index("right_heel_y_m")
    for st in course.steps:
        end = course.samples[np.argmin(np.abs(course.samples[:, 0] - st.end_s))]
        heel = end[hl if st.leg == "left" else hr]
        assert heel == pytest.approx(st.landing_y)
        assert end[WALK_COLUMNS.index(f"{st.leg}_heel_z_m")] == 0.0
        assert _flat_around(ter, heel - r.stand + 1e-6, heel + FOOT + r.stand - 1e-6)
    # The legs swap roles at a landing: the foot that landed stands where it landed during the next swing.
    for a, b in zip(course.steps, course.steps[1:]):
        assert b.pivot_y == a.landing_y
    doc = json.loads(course.to_json())
    assert doc["ok"] and len(doc["steps"]) == len(course.steps)
    step = doc["steps"][0]
    assert {"columns", "samples", "landing", "method"} <= set(step) and step["method"] == "cfftg"
    assert len(step["samples"][0]) == len(step["columns"])


def _random_rl(seed=0):
    from conftest import random_generator

    return random_generator(CFG, seed)


def test_rl_walk_reports_fallbacks_per_step_and_stops_at_a_failed_swing_without_them():
    gen = _random_rl()
    ter = Terrain.from_points(BLOCK)
    with_fb = plan_course(gen, ter, rate=50)
    assert with_fb.ok, with_fb.reasons
    assert set(with_fb.methods) <= {"rl", "cfftg-fallback"}
    assert [
        f"step {s.index + 1}: cfftg-fallback" for s in with_fb.steps if s.method == "cfftg-fallback"
    ] == list(with_fb.notes)
    alone = plan_course(gen, ter, rate=50, fallback=None)
    assert set(alone.methods) == {"rl"}
    if (
        "cfftg-fallback" in with_fb.methods
    ):  # the random policy fails somewhere: RL alone stops there
        k = with_fb.methods.index("cfftg-fallback")
        assert not alone.ok and len(alone.steps) == k + 1 and alone.steps[k].timed is None
        assert alone.reasons[0].startswith(f"step {k + 1} (")


def test_double_support_holds_each_landing():
    ter = Terrain.from_points(BLOCK)
    base = plan_course(CFFTG(CFG), ter, rate=50)
    held = plan_course(CFFTG(CFG), ter, rate=50, double_support=0.2)
    n = len(held.steps) - 1
    assert held.duration == pytest.approx(base.duration + n * 0.2)
    hold = held.samples[held.samples[:, 2] == -1]
    assert len(hold) == n * 10
    assert np.all(hold[:, WALK_COLUMNS.index("hip_left_vel_rad_s") :] == 0.0)
    _check_walk_samples(held.samples, 50.0, held.limits)
    with pytest.raises(CourseError, match="double_support"):
        plan_course(CFFTG(CFG), ter, double_support=-1.0)
    with pytest.raises(CourseError, match="generator: expected"):
        plan_course(object(), ter)


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def test_cli_walk_writes_csv_and_json(tmp_path, capsys):
    t = _write(tmp_path, "t.csv", "\n".join(f"{y},{z}" for y, z in BLOCK))
    out, js = tmp_path / "w.csv", tmp_path / "w.json"
    rc = main(
        [
            "walk",
            "--method",
            "cfftg",
            "--terrain",
            str(t),
            "--out",
            str(out),
            "--json",
            str(js),
            "--rate",
            "50",
        ]
    )
    assert rc == 0, capsys.readouterr()
    doc = json.loads(js.read_text())
    assert doc["ok"] and doc["rate_hz"] == 50.0 and doc["steps"][0]["leg"] == "left"
    assert out.read_text().splitlines()[0].split(",") == list(WALK_COLUMNS)


def test_cli_walk_refuses_an_infeasible_course_writing_nothing(tmp_path, capsys):
    t = _write(tmp_path, "t.csv", "0,0\n0.6,0\n0.6,0.9\n0.7,0.9\n0.7,0\n2,0\n")
    out, js = tmp_path / "w.csv", tmp_path / "w.json"
    rc = main(
        ["walk", "--method", "cfftg", "--terrain", str(t), "--out", str(out), "--json", str(js)]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "y = 0.60-0.70 m" in err
    assert not out.exists() and not js.exists()
    bad = _write(tmp_path, "bad.csv", "0,0\n1,nan\n")
    assert main(["walk", "--method", "cfftg", "--terrain", str(bad), "--out", str(out)]) == 2
    assert "bad.csv, line 2" in capsys.readouterr().err and not out.exists()
    assert (
        main(
            [
                "walk",
                "--method",
                "cfftg",
                "--fallback",
                "none",
                "--terrain",
                str(t),
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert "--fallback" in capsys.readouterr().err
    assert main(["walk", "--method", "cfftg", "--terrain", str(t), "--out", str(t)]) == 2
    assert "--terrain input" in capsys.readouterr().err
    assert (
        main(["walk", "--method", "cfftg", "--terrain", str(t), "--steps", "0", "--out", str(out)])
        == 2
    )
    assert "steps: must be" in capsys.readouterr().err and not out.exists()
    assert main(["walk", "--terrain", str(t), "--out", str(out)]) == 2
    assert "--policy: required" in capsys.readouterr().err


def test_cli_generate_takes_a_profile_file(tmp_path, capsys):
    prof = _write(tmp_path, "p.csv", "y_m,z_m\n0.35,0\n0.40,0.12\n0.50,0.08\n0.55,0\n")
    out = tmp_path / "s.csv"
    assert main(["generate", "--method", "cfftg", "--profile", str(prof), "--out", str(out)]) == 0
    assert out.exists() and "profile" in capsys.readouterr().out
    bad = _write(tmp_path, "q.csv", "0.35,0\n0.30,0.1\n")
    assert (
        main(
            [
                "generate",
                "--method",
                "cfftg",
                "--profile",
                str(bad),
                "--out",
                str(tmp_path / "x.csv"),
            ]
        )
        == 2
    )
    assert "q.csv, line 2" in capsys.readouterr().err
    for extra in (["--obstacle", "base1"], ["--width", "0.1"]):
        assert (
            main(
                ["generate", "--method", "cfftg", "--profile", str(prof), *extra, "--out", str(out)]
            )
            == 2
        )
        assert "--profile" in capsys.readouterr().err
    assert main(["generate", "--method", "cfftg", "--out", str(out)]) == 2
    assert "--obstacle or --profile" in capsys.readouterr().err


# --------------------------------------------------------------------------------------------
# The benchmark part
# --------------------------------------------------------------------------------------------


def test_course_benchmark_figures_follow_from_its_rows(tmp_path, monkeypatch):
    from benchlib import course_bench
    from benchlib.run_all import summary_rows
    from test_reliability_inputs import make_policy

    # One short course with one obstacle: a few swings (the part's own sizes are for `jaxexo bench`).
    monkeypatch.setattr(course_bench, "LENGTH", (2.0, 2.0))
    monkeypatch.setattr(course_bench, "OBSTACLES", (1, 1))
    monkeypatch.setattr(course_bench, "START_FLAT", (0.9, 0.9))
    monkeypatch.setattr(course_bench, "REFERENCE_COURSES", 1)
    pol = make_policy(tmp_path / "policy.npz", cfg=CFG)
    log = tmp_path / "log.jsonl"
    res = course_bench.run_course_benchmark(pol, tmp_path, n=1, seed=3, progress=None, log=log)
    assert res["planned"] + res["refused"] == 1
    rows = res["courses"]
    assert res["rl_alone_success"] == (
        sum(r["rl"]["ok"] for r in rows) / len(rows) if rows else res["rl_alone_success"]
    )
    assert course_bench.summarize_log(log, 3)["planned"] == res["planned"]
    assert next(tmp_path.glob("course_*.md")).read_text().startswith("# Walks over courses")
    assert any("walks over" in r[0] for r in summary_rows({"course": res}))
    with pytest.raises(ValueError, match="n: the number of courses"):
        course_bench.run_course_benchmark(pol, None, n=0)


def test_drawn_courses_have_their_obstacles_on_the_floor():
    from benchlib.course_bench import GAP, draw_course

    rng = np.random.default_rng(1)
    for _ in range(20):
        pts, kinds = draw_course(rng)
        ter = Terrain.from_points(pts)  # a valid terrain: y non-decreasing, z >= 0, finite
        from jaxexo.course import obstacles_of

        obs = obstacles_of(ter)
        assert len(obs) <= len(kinds) and 3.0 <= ter.y[-1] <= 8.0 + 1e-9 or ter.y[-1] > 8.0
        gaps = [b[0, 0] - a[-1, 0] for a, b in zip(obs, obs[1:])]
        assert all(g >= GAP[0] - 1e-9 or g == 0.0 for g in gaps)


def test_plot_and_animation_of_a_walk(tmp_path):
    pytest.importorskip("matplotlib")
    from PIL import Image

    from jaxexo.plots.animate import animate_course
    from jaxexo.plots.plot import plot_course

    course = plan_course(CFFTG(CFG), Terrain.from_points(BLOCK), rate=50)
    plot_course(course, tmp_path / "w.png")
    animate_course(course, tmp_path / "w.gif", fps=3.0, hold_s=0.0, dpi=30)
    with Image.open(tmp_path / "w.png") as im:
        assert im.size[0] > im.size[1]
    with Image.open(tmp_path / "w.gif") as im:
        assert im.n_frames == len(np.arange(0.0, course.duration + 1e-9, 1 / 3.0))
    with pytest.raises(ValueError, match="fps"):
        animate_course(course, tmp_path / "x.gif", fps=0.0)


def test_a_walk_needs_numpy_only():
    import subprocess
    import sys

    from conftest import ROOT

    # A module set to None in sys.modules cannot be imported: JAX (and SciPy) are unavailable here.
    code = (
        "import sys\nfor m in ('jax', 'jaxlib', 'flax', 'optax', 'scipy'): sys.modules[m] = None\n"
        "from jaxexo.inference import plan_course, Terrain\nfrom jaxexo.baselines import CFFTG\n"
        f"c = plan_course(CFFTG(), Terrain.from_points({BLOCK!r}), rate=50)\n"
        "print('OK', c.ok, len(c.steps))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert "OK True 2" in out.stdout
