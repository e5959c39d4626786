"""The JSON's `piecewise` curve, evaluated as its `evaluate` text says by an evaluator written here
from that text alone (plain Horner steps and the chain rule, nothing of jaxexo's), is the checked
curve: equal to `swing.at(t)` to rounding on a 20 kHz grid and around every breakpoint, C2 at every
breakpoint, at rest at both ends and within the limits that `within_limits` promises, for swings of
both generators timed at 100 Hz, 1 kHz and 10 kHz. JAXEXO_PIECEWISE_SCALE=k multiplies the number of
swings (the CI run times 1,150; a run at scale 4 is quoted in docs/reliability.md)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.inference import Obstacle, TrajectoryGenerator
from jaxexo.physics.scenarios import batch_options
from jaxexo.swing.limits import DeviceLimits
from jaxexo.swing.timing import time_swing, time_swings

from benchlib.scenes import safety_sets
from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"
SCALE = int(os.environ.get("JAXEXO_PIECEWISE_SCALE", "1"))
# Swings per generator at each rate, and how many of them are evaluated on the whole 20 kHz grid
# (all of them are evaluated at and around every breakpoint and on a 2 kHz grid).
COUNTS = {100.0: 250, 1000.0: 250, 10_000.0: 75}
DENSE_EVERY = 5


class JsonCurve:
    """The curve of a `--json` document's `piecewise` entry, as its `evaluate` text says."""

    def __init__(self, doc: dict):
        pw = doc["piecewise"]
        self.tb = np.array(pw["time_law"]["breakpoints_s"], dtype=np.float64)
        self.tc = np.array(pw["time_law"]["coefficients"], dtype=np.float64)  # (P, 4)
        self.sb = np.array(pw["joint_path"]["breakpoints"], dtype=np.float64)
        self.qc = np.array(pw["joint_path"]["coefficients"], dtype=np.float64)  # (J, M, 4)
        self.duration = doc["duration_s"]

    @staticmethod
    def _poly(c: np.ndarray, d: np.ndarray) -> list[np.ndarray]:
        """sum_k c_k d^k and its first three derivatives in d (c: (n, 4))."""
        c0, c1, c2, c3 = c.T
        return [
            c0 + d * (c1 + d * (c2 + d * c3)),
            c1 + d * (2.0 * c2 + d * 3.0 * c3),
            2.0 * c2 + d * 6.0 * c3,
            6.0 * c3,
        ]

    def law(self, t: np.ndarray, piece: np.ndarray | None = None) -> list[np.ndarray]:
        """S, S', S'', S''' at t: the last piece whose breakpoint is <= t, unless ``piece`` says."""
        t = np.clip(t, 0.0, self.tb[-1])
        if piece is None:
            piece = np.searchsorted(self.tb, t, side="right") - 1
            piece = np.clip(piece, 0, len(self.tc) - 1)
        return self._poly(self.tc[piece], t - self.tb[piece])

    def path(self, s: np.ndarray, piece: np.ndarray | None = None) -> list[np.ndarray]:
        """Q_j(s) and its s-derivatives, (n, J) each."""
        if piece is None:
            piece = np.clip(np.searchsorted(self.sb, s, side="right") - 1, 0, self.qc.shape[1] - 1)
        per_joint = [self._poly(c[piece], s - self.sb[piece]) for c in self.qc]
        return [np.stack([p[o] for p in per_joint], axis=1) for o in range(4)]

    def joints(self, t: np.ndarray) -> list[np.ndarray]:
        """q, q', q'', q''' at t (n, J) each, by the chain rule."""
        s, s1, s2, s3 = (x[:, None] for x in self.law(t))
        q, d1, d2, d3 = self.path(s[:, 0])
        return [
            q,
            d1 * s1,
            d2 * s1 * s1 + d1 * s2,
            d3 * s1**3 + 3.0 * d2 * s1 * s2 + d1 * s3,
        ]


def _swings(rate: float) -> list:
    rl = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(rl.config)
    n = COUNTS[rate] * SCALE
    trajs = {"rl": [], "cfftg": []}
    # Each rate its own scenes (the unseen shapes and held-out families drawn with its own seed).
    for scenes in safety_sets(rl.config, n, shapes_seed=int(rate)).values():
        obs, kw = [s.obstacle for s in scenes], batch_options(scenes)
        trajs["rl"] += [t for t in rl.generate_batch(obs, fallback=None, **kw) if t.ok]
        trajs["cfftg"] += [t for t in cf.generate_batch(obs, **kw) if t.ok]
    pick = trajs["rl"][:n] + trajs["cfftg"][:n]
    assert len(pick) == 2 * n
    return rl.config, time_swings(pick, rl.config, rate=rate)


def _agreement(sw, curve: JsonCurve, dense: bool) -> tuple[float, float, float]:
    """The largest |q_json - q| (rad), |q'_json - q'| (rad/s), |q''_json - q''| (rad/s^2) over the
    grid, the breakpoints, a hair either side of them and the pieces' middles."""
    b = curve.tb
    grid = np.arange(0.0, sw.duration, 1.0 / (20_000.0 if dense else 2_000.0))
    t = np.concatenate([grid, b, b - 1e-9, b + 1e-9, 0.5 * (b[:-1] + b[1:]), [sw.duration]])
    t = np.clip(t, 0.0, sw.duration)
    mine, (_, ref) = curve.joints(t), sw.curve.joints(t)  # swing.at's joints, less the kinematics
    return tuple(float(np.abs(a - r).max()) for a, r in zip(mine[:3], ref[:3]))


def _c2_jumps(curve: JsonCurve) -> tuple[float, float]:
    """The largest jump of S, S', S'' across the time law's breakpoints (relative to each
    derivative's largest value) and of Q, Q', Q'' across the path's."""
    inner = np.arange(len(curve.tc) - 1)
    left = curve.law(curve.tb[1:-1], inner)
    right = curve.law(curve.tb[1:-1], inner + 1)
    scale = [np.abs(x).max() for x in curve.law(np.linspace(0, curve.duration, 4001))]
    law = max(float(np.abs(left[o] - right[o]).max() / scale[o]) for o in range(3))
    inner = np.arange(curve.qc.shape[1] - 1)
    left = curve.path(curve.sb[1:-1], inner)
    right = curve.path(curve.sb[1:-1], inner + 1)
    scale = [np.abs(x).max() for x in curve.path(np.linspace(0, 1, 4001))]
    path = max(float(np.abs(left[o] - right[o]).max() / scale[o]) for o in range(3))
    return law, path


@pytest.mark.slow
@pytest.mark.parametrize("rate", list(COUNTS))
def test_the_json_curve_is_the_checked_curve(rate):
    config, timed = _swings(rate)
    planned = DeviceLimits.from_config(config).planned()
    limits = [np.asarray(x) for x in (planned.velocity, planned.acceleration, planned.jerk)]
    worst = np.zeros(3)
    for i, sw in enumerate(timed):
        assert sw.ok, sw.reasons
        # Through JSON text, as a controller reads it (to_json's "piecewise" is this entry: see
        # the test below; its 10 kHz samples would only slow this one down).
        doc = {"piecewise": sw.curve.piecewise(), "duration_s": sw.duration}
        curve = JsonCurve(json.loads(json.dumps(doc)))
        dense = i % DENSE_EVERY == 0
        err = _agreement(sw, curve, dense)
        worst = np.maximum(worst, err)
        law_jump, path_jump = _c2_jumps(curve)
        assert law_jump < 1e-9 and path_jump < 1e-9, (i, law_jump, path_jump)
        # At rest at both ends: S = 0 then 1, S' = S'' = 0.
        start, end = curve.law(np.array([0.0])), curve.law(np.array([curve.duration]))
        assert abs(start[0][0]) < 1e-15 and abs(end[0][0] - 1.0) < 1e-12, i
        for o in (1, 2):
            assert abs(start[o][0]) < 1e-9 and abs(end[o][0]) < 1e-9, (i, o, end[o][0])
        # Within the limits `within_limits` promises, on the JSON's own curve at 20 kHz (2 kHz
        # and every breakpoint when not dense).
        grid = np.arange(0.0, curve.duration, 1.0 / (20_000.0 if dense else 2_000.0))
        t = np.concatenate([grid, curve.tb, 0.5 * (curve.tb[:-1] + curve.tb[1:])])
        _, v, a, j = curve.joints(t)
        for x, lim in zip((v, a, j), limits):
            assert np.all(np.abs(x) <= lim * (1.0 + 1e-9)), (i, np.abs(x).max(0) / lim)
    # To rounding: 1e-12 rad, 1e-9 rad/s and rad/s^2.
    assert worst[0] <= 1e-12 and worst[1] <= 1e-9 and worst[2] <= 1e-9, worst


def test_the_reported_swing_keeps_each_piece_on_its_own_jerk():
    """The issue's example (a triangle 12.22 cm wide, 8.69 cm high at 36.79 cm, between the feet,
    start 0.86 cm, step 55.85 cm, RL alone, 100 Hz): on 46d0ad3 pieces that start at a node + the
    window took their left neighbour's jerk, and the JSON curve broke the acceleration limit."""
    gen = TrajectoryGenerator.load(POLICY)
    tri = Obstacle.triangle(0.1222, 0.0869, center_y=0.3679)
    traj = gen.generate(tri, pivot="between", start_y=0.0086, step_length=0.5585, fallback=None)
    sw = time_swing(traj, gen.config, rate=100.0)
    doc = json.loads(sw.to_json())
    assert doc["piecewise"] == json.loads(json.dumps(sw.curve.piecewise()))
    curve = JsonCurve(doc)
    # Each piece's cubic term is the jerk of s in the middle of the piece.
    mid = 0.5 * (curve.tb[:-1] + curve.tb[1:])
    np.testing.assert_array_equal(curve.tc[:, 3], sw.curve.law.at(mid)[3] / 6.0)
    assert max(_agreement(sw, curve, dense=True)) <= 1e-9
    t = np.linspace(0.0, sw.duration, 1001)
    np.testing.assert_allclose(curve.joints(t)[0], sw.at(t).joint_angles, rtol=0, atol=1e-12)
    assert max(_c2_jumps(curve)) < 1e-9
