"""The swing API's checks and size bounds: times checked when given and the legs at
rest outside the swing (``SwingCurve.at``), ``DeviceLimits`` and ``GenerateOptions`` checked when
made, sizes bounded by the memory this process may use (``ulimit -v`` included) before any work
(``time_swing``, ``swing.at``, ``jaxexo walk``), and dense paths timed as the path they are (the
timed curve's verdict checked against an independent dense distance to the obstacle)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.config import load_config
from jaxexo.inference import GenerateOptions, Obstacle
from jaxexo.swing.timing import DeviceLimits, time_swing

from conftest import ROOT, cli_cmd, random_generator, run_python

CFG = load_config(ROOT / "configs" / "default.toml")


@pytest.fixture(scope="module")
def swing():
    return time_swing(CFFTG(CFG).generate(Obstacle.named("base1")), CFG, rate=100)


# --------------------------------------------------------------------------------------------
# Times checked when given; the legs rest outside the swing
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "t, shown",
    [
        ("0.4", "'0.4'"),
        (True, "True"),
        (None, "None"),
        (1j, "1j"),
        (np.complex128(0.2), "np.complex128"),
        ([0.1, None], "[0.1, None]"),
        (["0.4"], "['0.4']"),
        (np.array([True, False]), "array([ True, False])"),
    ],
)
def test_swing_at_refuses_what_is_not_a_time_naming_t_and_the_value(swing, t, shown):
    with pytest.raises(TypeError, match=r"^t: expected times in s") as e:
        swing.at(t)
    assert shown in str(e.value)
    with pytest.raises(TypeError, match=r"^t: expected times in s"):
        swing.curve.at(t)


def test_swing_at_refuses_non_finite_and_two_dimensional_times(swing):
    with pytest.raises(ValueError, match=r"^t: expected finite times in s, got nan"):
        swing.at(float("nan"))
    with pytest.raises(ValueError, match=r"shape \(2, 1\)"):
        swing.at([[0.1], [0.2]])
    # Real numbers of every kind are times.
    for t in (0, 0.5, np.float32(0.5), np.int64(1), [0, 0.5], np.array([0.25])):
        assert np.all(np.isfinite(swing.at(t).joint_angles))


def test_the_legs_rest_before_lift_off_and_after_landing(swing):
    d = swing.duration
    st = swing.at([-1.0, -1e-9, 0.0, d, d + 1e-9, d + 5.0])
    derivatives = (
        st.joint_velocity,
        st.joint_acceleration,
        st.joint_jerk,
        st.heel_velocity,
        st.heel_acceleration,
        st.heel_jerk,
    )
    for x in derivatives:
        assert np.all(x[[0, 1, 3, 4, 5]] == 0.0), x
    # Positions: the end poses, exactly.
    for x in (st.joint_angles, st.heel, st.toe, st.hip, st.knee_swing, st.knee_stance):
        assert np.array_equal(x[0], x[2]) and np.array_equal(x[1], x[2])
        assert np.array_equal(x[4], x[3]) and np.array_equal(x[5], x[3])
    assert list(st.path_parameter) == [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
    # At lift-off itself the jerk is the first piece's (right-continuous): the swing starts there.
    assert np.any(st.joint_jerk[2] != 0.0)


# --------------------------------------------------------------------------------------------
# Limits and options checked when made
# --------------------------------------------------------------------------------------------


def test_device_limits_take_the_configs_bound_on_the_swing_duration():
    base = DeviceLimits.from_config(CFG)
    for bad in (1000.0, 60.5, float("inf"), True, "1"):
        with pytest.raises(ValueError, match=r"limits\.min_duration: .*\[0, 60\]"):
            DeviceLimits(base.velocity, base.acceleration, bad, base.jerk)
    assert DeviceLimits(base.velocity, base.acceleration, 60, base.jerk).min_duration == 60.0


def test_a_swing_longer_than_a_minute_is_never_within_the_limits():
    """Limits far below any drive's (scaled, as the replays scale them) need a swing over 60 s: it
    is sampled as the longest swing (60 s), never within the limits, with a note saying why."""
    traj = CFFTG(CFG).generate(Obstacle.named("base1"))
    slow = DeviceLimits.from_config(CFG).scaled(0.004, 0.004)
    sw = time_swing(traj, CFG, rate=10, limits=slow)
    assert sw.duration <= 60.0 + 1e-9
    assert not sw.within_limits and not sw.ok
    assert any("longer than the longest swing (60 s)" in n for n in sw.notes), sw.notes


def test_generate_options_refuse_a_pivot_condition_with_a_pivot_y():
    with pytest.raises(ValueError, match=r"^pivot, pivot_y: give one of them.*'agent'.*0\.3"):
        GenerateOptions(pivot="agent", pivot_y=0.3)
    with pytest.raises(ValueError, match=r"^pivot\[1\], pivot_y: give one of them"):
        GenerateOptions(pivot=[None, "between"], pivot_y=0.3)
    with pytest.raises(ValueError, match=r"^pivot\[0\], pivot_y\[0\]"):
        GenerateOptions(pivot=["agent", None], pivot_y=[0.2, None])
    # One of them per obstacle is what generate_batch takes.
    GenerateOptions(pivot=["agent", None], pivot_y=[None, 0.3])
    GenerateOptions(pivot="between")
    GenerateOptions(pivot_y=0.3)


# --------------------------------------------------------------------------------------------
# Sizes bounded by the process's own memory
# --------------------------------------------------------------------------------------------

# Run in a subprocess whose address space is capped (``ulimit -v``) at its present size plus
# HEADROOM: what it may still allocate, whatever the machine has.
LIMITED = """
import resource
def cap(headroom):
    with open("/proc/self/status") as f:
        size = next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:"))
    resource.setrlimit(resource.RLIMIT_AS, (size + headroom, resource.RLIM_INFINITY))
"""


def test_the_memory_the_guards_count_is_the_processs():
    r = run_python(
        LIMITED
        + """
import numpy
from jaxexo.config.memory import process_memory_bytes, machine_memory_bytes
cap(300 * 2**20)
room = process_memory_bytes()
assert 0 < room <= 300 * 2**20, room
print("ok", room, machine_memory_bytes())
""",
        timeout=120,
    )
    assert r.returncode == 0 and r.stdout.startswith("ok"), r.stderr[-2000:]


def test_time_swing_refuses_what_the_process_limit_cannot_hold():
    """A 60 s swing at 10 kHz (600,000 samples) under ``ulimit -v`` of 200 MB more: refused naming
    the rate and the count; it ended in MemoryError when the guard counted the machine."""
    r = run_python(
        LIMITED
        + """
from jaxexo.baselines import CFFTG
from jaxexo.config import Config
from jaxexo.inference import Obstacle
from jaxexo.swing.timing import DeviceLimits, time_swing
cfg = Config()
traj = CFFTG(cfg).generate(Obstacle.named("base1"))
base = DeviceLimits.from_config(cfg)
limits = DeviceLimits(base.velocity, base.acceleration, 60.0, base.jerk, base.headroom)
cap(200 * 2**20)
try:
    time_swing(traj, cfg, rate=10000, limits=limits)
except ValueError as e:
    print("refused:", e)
""",
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("refused: rate: a 60 s swing at 10000 Hz needs 6e+05 samples")
    assert "half the memory this process may use" in r.stdout


def test_swing_at_refuses_more_times_than_the_process_holds_before_allocating():
    """2e8 times (a zero-stride view: no memory of its own) under ``ulimit -v`` of 1 GB more: one
    clear refusal naming the count and the bound, not a MemoryError."""
    r = run_python(
        LIMITED
        + """
import numpy as np
from jaxexo.baselines import CFFTG
from jaxexo.config import Config
from jaxexo.inference import Obstacle
from jaxexo.swing.timing import time_swing
cfg = Config()
sw = time_swing(CFFTG(cfg).generate(Obstacle.named("base1")), cfg)
cap(2**30)
try:
    sw.at(np.broadcast_to(0.5, (200_000_000,)))
except ValueError as e:
    print("refused:", e)
""",
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("refused: t: 200000000 times need about 191 GiB")
    assert "half the memory this process may use holds" in r.stdout


def test_walk_refuses_a_course_too_large_for_the_process_before_any_work(tmp_path):
    """``walk --rate 10000 --json`` over a 100 m course under ``ulimit -v`` of 3 GB: refused within
    seconds by its estimate, naming --rate and the course, and nothing written (it ran for minutes
    and died in MemoryError leaving a 785 MB CSV)."""
    import resource

    terrain = tmp_path / "flat.csv"
    terrain.write_text("0,0\n100,0\n")
    out, js = tmp_path / "w.csv", tmp_path / "w.json"

    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2**30, resource.RLIM_INFINITY))

    argv = cli_cmd("walk", "--method", "cfftg", "--terrain", terrain, "--rate", 10000)
    r = subprocess.run(
        [*argv, "--out", out, "--json", js],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        preexec_fn=cap,
    )
    assert r.returncode == 2, r.stderr[-2000:]
    err = r.stderr.strip()
    assert err.startswith("jaxexo: error: --rate: a walk of 235 swings over 99.76 m of course")
    assert "at 10000 Hz takes at least" in err and "29 columns" in err and "--json" in err
    assert "Traceback" not in r.stderr
    assert not out.exists() and not js.exists() and list(tmp_path.iterdir()) == [terrain]


def test_plan_course_refuses_a_walk_the_memory_cannot_hold(monkeypatch):
    from jaxexo.config import memory
    from jaxexo.course import CourseError, Terrain, plan_course

    monkeypatch.setattr(memory, "process_memory_bytes", lambda: 64 * 2**20)
    ter = Terrain.from_points([[0.0, 0.0], [20.0, 0.0]])
    with pytest.raises(CourseError, match=r"^rate: a walk of \d+ swings over 19\.76 m") as e:
        plan_course(CFFTG(CFG), ter, rate=5000)
    assert "lower rate or walk a shorter course (goal_y, steps)" in str(e.value)


# --------------------------------------------------------------------------------------------
# Dense paths are timed as the path they are
# --------------------------------------------------------------------------------------------


def _segment_distance(a0, a1, b0, b1) -> np.ndarray:
    """Distance between 2-D segments a (n,) and b (m,): (n, m); 0 where they cross."""

    def point_segment(p, s0, s1):
        d = s1 - s0
        u = np.clip(
            np.einsum("...k,...k", p - s0, d) / np.maximum(np.einsum("...k,...k", d, d), 1e-300),
            0,
            1,
        )
        return np.linalg.norm(p - (s0 + u[..., None] * d), axis=-1)

    A0, A1 = a0[:, None], a1[:, None]
    B0, B1 = b0[None], b1[None]
    dist = np.minimum.reduce(
        [
            point_segment(A0, B0, B1),
            point_segment(A1, B0, B1),
            point_segment(B0, A0, A1),
            point_segment(B1, A0, A1),
        ]
    )

    def side(p, q, r):
        return np.sign(
            (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
            - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
        )

    cross = (side(A0, A1, B0) * side(A0, A1, B1) < 0) & (side(B0, B1, A0) * side(B0, B1, A1) < 0)
    return np.where(cross, 0.0, dist)


def dense_clearance(sw, n: int = 40_001) -> float:
    """Independent of the verdict: the flat foot (heel to toe) of the timed curve at n instants
    against every edge of the obstacle's outline, the least distance (m)."""
    st = sw.at(np.linspace(0.0, sw.duration, n))
    outline = np.asarray(sw.scene.obstacle.outline, np.float64)
    return float(_segment_distance(st.heel, st.toe, outline[:-1], outline[1:]).min())


@pytest.mark.parametrize("n_points", [5000, 20000])
@pytest.mark.parametrize("method", ["cfftg", "rl"])
def test_a_dense_path_is_timed_as_the_path_it_is(method, n_points):
    """At 5,000 and 20,000 points the timed swing takes the time the 100-point one takes (not a
    0.36 s straight joint line into the obstacle, nor a swing slowed several times), passes where
    its path passes, and its clearance, measured independently on a dense grid of the curve, is at
    least what its verdict states."""
    if method == "cfftg":
        gen, kw = CFFTG(CFG), {}
    else:  # a random policy's own swing (seed 2 keeps this one safe), not CFFTG's fallback
        gen, kw = random_generator(CFG, 2), {"fallback": None}
    ob = Obstacle.named("triangle")
    coarse = time_swing(gen.generate(ob, n_points=100, **kw), CFG, rate=100)
    traj = gen.generate(ob, n_points=n_points, **kw)
    sw = time_swing(traj, CFG, rate=100)
    assert traj.ok and sw.ok == traj.ok, sw.reasons
    assert sw.duration == pytest.approx(coarse.duration, rel=0.05)
    dense = dense_clearance(sw)
    assert dense >= sw.checks.min_clearance - 1e-9
    assert dense >= CFG.env.min_clearance
    assert dense == pytest.approx(traj.checks.min_clearance, abs=1e-3)


def test_generate_100000_points_gives_a_timed_swing_that_follows_its_path(tmp_path):
    import json

    js = tmp_path / "g.json"
    r = subprocess.run(
        cli_cmd(
            "generate",
            "--method",
            "cfftg",
            "--obstacle",
            "base1",
            "--points",
            100000,
            "--rate",
            100,
            "--out",
            tmp_path / "g.csv",
            "--json",
            js,
        ),
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    doc = json.loads(js.read_text())
    assert doc["checks"]["ok"] and doc["checks"]["within_limits"]
    coarse = time_swing(CFFTG(CFG).generate(Obstacle.named("base1")), CFG, rate=100)
    assert doc["duration_s"] == pytest.approx(coarse.duration, rel=0.05)
    # The exported samples against the obstacle, independently: heel and toe at 100 Hz.
    cols = doc["columns"]
    s = np.array(doc["samples"])
    heel = s[:, [cols.index("heel_y_m"), cols.index("heel_z_m")]]
    toe = s[:, [cols.index("toe_y_m"), cols.index("toe_z_m")]]
    outline = np.array(doc["scene"]["outline"])
    d = _segment_distance(heel, toe, outline[:-1], outline[1:]).min()
    assert d >= CFG.env.min_clearance and d >= doc["checks"]["min_clearance"] - 1e-9
