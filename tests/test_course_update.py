"""A walk told of a new terrain while it goes (``plan_course(updates=...)``, ``jaxexo walk
--update-at T --update-terrain FILE``): the swing in flight at T is replanned over the new terrain's
obstacle, the swings after it are planned on the new terrain, the footholds stay. Checked against
the walk without the update (the same samples before T) and by the samples alone (continuous,
within the limits by finite differences, across the switch and every hand-over); updates that
would move a foothold, or come after the walk, are refused by name."""

from __future__ import annotations

import json

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.cli import main
from jaxexo.config import Config
from jaxexo.course import CourseError, Terrain, TerrainUpdate, plan_course
from jaxexo.inference import TrajectoryGenerator

from conftest import ROOT
from test_course import BLOCK, _check_walk_samples

CFG = Config()
POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
# The block of BLOCK measured 3 cm taller once the walk is under way.
TALLER = [[0.0, 0.0], [0.5, 0.0], [0.55, 0.13], [0.65, 0.13], [0.7, 0.0], [1.4, 0.0]]
# A second block where the first swing lands (0.85 m): the footholds would have to move.
ON_FOOTHOLD = BLOCK[:-1] + [[0.84, 0.0], [0.88, 0.05], [0.92, 0.0], [1.4, 0.0]]


def _walks(gen, t_frac: float = 0.3):
    ter = Terrain.from_points(BLOCK)
    base = plan_course(gen, ter, rate=50)
    first = base.steps[0]
    t = first.start_s + t_frac * first.timed.duration
    return base, plan_course(gen, ter, rate=50, updates=TerrainUpdate(t, TALLER)), t


def _same_before(base, new, t: float) -> None:
    """The walk's samples before ``t`` are those of the walk without the update (to rounding)."""
    n = int(np.searchsorted(base.samples[:, 0], t))
    assert n > 3
    np.testing.assert_allclose(new.samples[:n], base.samples[:n], rtol=0, atol=1e-12)


def _gen(method):
    return CFFTG(CFG) if method == "cfftg" else TrajectoryGenerator.load(POLICY)


@pytest.mark.parametrize("method", ["cfftg", "rl"])
def test_the_swing_in_flight_is_replanned_and_the_walk_stays_continuous(method):
    base, new, t = _walks(_gen(method), 0.2)
    assert base.ok, base.reasons
    assert new.ok, new.reasons
    st = new.steps[0]
    assert st.replanned_from is not None and st.timed.switch_times == (pytest.approx(t),)
    assert st.timed.scene.height == pytest.approx(0.13)
    assert st.replanned_from.scene.height == pytest.approx(0.10)
    np.testing.assert_array_equal(st.replanned_from.joint_angles, base.steps[0].timed.joint_angles)
    _same_before(base, new, t)
    # Independent of the planner: continuous and within the limits across the switch and the
    # hand-over, at rest at both ends.
    assert new.junction_jump <= 1e-6
    _check_walk_samples(new.samples, 50.0, new.limits)
    # The footholds stay; the swing after the update is planned on the new terrain.
    assert new.footholds == base.footholds and len(new.steps) == len(base.steps)
    assert new.steps[1].replanned_from is None and new.steps[1].timed.scene.height == 0.13
    doc = json.loads(new.to_json())
    assert doc["updates"][0]["time_s"] == t
    assert doc["steps"][0]["switch_times_s"] == [pytest.approx(t)]
    assert doc["steps"][1]["switch_times_s"] == []


# The block 30 cm tall, known late in the first swing: no continuation clears it.
WALL = [[0.0, 0.0], [0.5, 0.0], [0.55, 0.3], [0.65, 0.3], [0.7, 0.0], [1.4, 0.0]]


@pytest.mark.parametrize("method", ["cfftg", "rl"])
def test_a_replan_with_no_safe_continuation_stops_the_walk_saying_why(method):
    gen = _gen(method)
    ter = Terrain.from_points(BLOCK)
    base = plan_course(gen, ter, rate=50)
    t = 0.4 * base.steps[0].timed.duration
    new = plan_course(
        gen, ter, rate=50, updates=[TerrainUpdate(t, WALL), TerrainUpdate(2.0, BLOCK)]
    )
    st = new.steps[0]
    assert not new.ok and not st.ok and len(new.steps) == 1 and st.timed.switch_times
    assert new.reasons[0].startswith("step 1 (") and "steps 2-2 not planned" in new.reasons[-1]
    # The swing was under way: its samples are the walk's, the same as planned before t.
    _same_before(base, new, t)
    assert new.duration == pytest.approx(st.timed.time[-1])
    assert new.notes[-1].startswith("updates[1] (t = 2 s) not applied: the walk stopped")


def test_an_update_between_swings_replans_nothing_and_plans_the_next_swing_on_it():
    gen = CFFTG(CFG)
    ter = Terrain.from_points(BLOCK)
    base = plan_course(gen, ter, rate=50, double_support=0.2)
    t = base.steps[0].end_s + 0.1  # both feet on the ground
    new = plan_course(gen, ter, rate=50, double_support=0.2, updates=[TerrainUpdate(t, TALLER)])
    assert all(s.replanned_from is None for s in new.steps)
    _same_before(base, new, t)
    h0 = [s.timed.scene.height for s in base.steps]
    h1 = [s.timed.scene.height for s in new.steps]
    assert h1[0] == h0[0] and h1[1] != h0[1]
    # The second swing over the taller block: as if planned with it from the start.
    alone = plan_course(gen, Terrain.from_points(TALLER), rate=50, double_support=0.2)
    np.testing.assert_array_equal(
        new.steps[1].timed.joint_angles, alone.steps[1].timed.joint_angles
    )


def test_bad_updates_are_refused_by_name():
    gen = CFFTG(CFG)
    ter = Terrain.from_points(BLOCK)
    with pytest.raises(
        CourseError, match=r"updates\[0\] \(t = 0.3 s\): a foot lands at y = 0.850 m"
    ):
        plan_course(gen, ter, rate=50, updates=TerrainUpdate(0.3, ON_FOOTHOLD))
    # Named by its place in the list given (the later of the two).
    with pytest.raises(CourseError, match=r"updates\[0\] \(t = 100 s\): the walk has landed"):
        plan_course(
            gen, ter, rate=50, updates=[TerrainUpdate(100, TALLER), TerrainUpdate(0, BLOCK)]
        )
    with pytest.raises(CourseError, match=r"updates\[0\].time: must be a finite number >= 0"):
        plan_course(gen, ter, updates=TerrainUpdate(-1.0, TALLER))
    with pytest.raises(CourseError, match=r"updates\[1\]: at t = 0.5 s, the time of updates\[0\]"):
        plan_course(gen, ter, updates=[TerrainUpdate(0.5, TALLER), TerrainUpdate(0.5, BLOCK)])
    with pytest.raises(CourseError, match=r"updates\[0\]: expected a TerrainUpdate"):
        plan_course(gen, ter, updates=[(0.5, TALLER)])
    with pytest.raises(CourseError, match="updates: expected a TerrainUpdate or a list"):
        plan_course(gen, ter, updates="t.csv")


def _write(tmp_path, name, pts) -> str:
    p = tmp_path / name
    p.write_text("\n".join(f"{y},{z}" for y, z in pts) + "\n")
    return str(p)


def test_cli_walk_with_an_update(tmp_path, capsys):
    t, tall = _write(tmp_path, "t.csv", BLOCK), _write(tmp_path, "tall.csv", TALLER)
    out, js, png = tmp_path / "w.csv", tmp_path / "w.json", tmp_path / "w.png"
    args = ["walk", "--method", "cfftg", "--terrain", t, "--rate", "50", "--out", str(out)]
    rc = main(
        args
        + ["--json", str(js), "--plot", str(png), "--update-at", "0.3"]
        + ["--update-terrain", tall]
    )
    doc = json.loads(js.read_text())
    assert rc == (0 if doc["ok"] else 1), capsys.readouterr()
    assert doc["updates"] == [{"time_s": 0.3, "terrain": tall, "points": TALLER}]
    assert doc["steps"][0]["switch_times_s"] == [pytest.approx(0.3)]
    assert "replanned at 0.300 s" in capsys.readouterr().out
    assert png.read_bytes()[:4] == b"\x89PNG"
    on = _write(tmp_path, "on.csv", ON_FOOTHOLD)
    for extra, message in (
        (["--update-at", "0.3"], "--update-terrain: give one per --update-at"),
        (["--update-terrain", tall], "--update-at: give one per --update-terrain"),
        (["--update-at", "nan", "--update-terrain", tall], "--update-at: must be a finite number"),
        (
            ["--update-at", "0.3", "--update-terrain", tall] * 2,
            "--update-at: 0.3 s is given twice",
        ),
        (
            ["--update-at", "0.3", "--update-terrain", on],
            f"--update-at 0.3 (--update-terrain {on}): a foot lands at y = 0.850 m",
        ),
        (["--update-at", "0.3", "--update-terrain", str(out)], "is the --update-terrain input"),
    ):
        out.unlink(missing_ok=True)
        assert main(args + extra) == 2
        err = capsys.readouterr().err
        assert err.startswith("jaxexo: error: ") and message in err, err
        assert not out.exists()
