"""The generators' outputs on a fixed set of scenes, for tests/test_reference_outputs.py.

The RL generator (the default config's policy, stored as tests/data/reference/policy.npz) and CFFTG
(the same policy's kinematics) generate every scene of ``scene_sets``: the training distribution,
the three safety sets (the thesis five shifted, unseen shapes, held-out families) and a set with
non-default options (a wider clearance, another smoothing, no fallback, fewer points). A subset is
timed for the device (``time_swings``). ``outputs`` returns the samples, verdicts and timed swings
as flat arrays (the joint angles through the timed swings); the stored copy (tests/data/reference/outputs.npz) was written from the code before
a refactor that must not change them, so a difference is a change of behaviour.

``python tests/reference_outputs.py --write`` rewrites the stored copy: only for a deliberate change
of behaviour, never to make the test pass.

``outputs(sensitivity=d)`` also fills ``d`` with how each timed swing responds to rounding
(``timing_sensitivity``): not stored, measured on the machine that runs the test, so that the
comparison's tolerance on a timed swing follows the timing code as it is (whatever its time law).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.inference import GenerateOptions, TrajectoryGenerator, time_swings
from jaxexo.inference.scenarios import training_scenarios
from jaxexo.physics.scenarios import batch_options

from benchlib.scenes import safety_sets

DATA = Path(__file__).resolve().parent / "data" / "reference"
POLICY = DATA / "policy.npz"
STORED = DATA / "outputs.npz"

# The verdict's booleans and numbers stored per swing (Trajectory.checks fields, batched).
FLAGS = (
    "ok",
    "reached_goal",
    "collision_free",
    "clearance_ok",
    "joint_limits_ok",
    "leg_length_ok",
    "above_ground",
)
NUMBERS = ("min_clearance", "heel_backward", "deviation", "smoothing")
TIMED_PER_SET = 40  # swings of each set timed, per generator
# How a timed swing's rounding is probed: its heel path's interior points (float64) moved by k ulps
# of its largest coordinate, up or down at random per coordinate, for each k (_probe). Another CPU's BLAS changes the heel by a few ulps of float64: the
# smoothing's and the landing's matrix products (dgemm, rows of 10 to 100 terms) are summed in
# another order and fused differently, an error bounded by n eps sum|a_i b_i| and typically a few
# eps; the same happens here when a swing is generated in a batch of another size (another blocking).
# 1, 4 and 16 ulps span that; the timing's response to them is not proportional to their size (its
# time law makes discrete choices), so the test takes the largest of the three.
PROBE_ULPS = (1, 4, 16)
PROBE_SEED = 0


def scene_sets(config) -> dict[str, tuple[list[dict], GenerateOptions]]:
    """The sets by name: their scenes (``generate`` keywords plus ``obstacle``) and options."""
    safety = safety_sets(config, 350)
    fewer = GenerateOptions(n_points=50)
    wider = GenerateOptions(n_points=60, clearance=0.03, smoothing=0.002, fallback=None)
    return {
        "training": (training_scenarios(config, 750), GenerateOptions()),
        **{name: (scenes, fewer) for name, scenes in safety.items()},
        "wider clearance": (training_scenarios(config, 200, seed=99), wider),
    }


def _probe(traj, ulps: int, rng):
    """``traj`` with its heel's interior points moved by ``ulps`` ulps of the path's largest
    coordinate (a dot product's rounding scales with its terms, not its result), each coordinate
    up or down at random; the ends, pinned by the generator, stay."""
    heel = np.array(traj.heel, np.float64)
    step = ulps * np.finfo(np.float64).eps * np.abs(heel).max()
    heel[1:-1] += step * rng.choice([-1.0, 1.0], heel[1:-1].shape)
    return dataclasses.replace(traj, heel=heel)


def timing_sensitivity(trajs: list, timed: list, config) -> dict[str, np.ndarray]:
    """How the timed swings ``timed`` (time_swings of ``trajs``) respond to rounding: each swing's
    heel perturbed by PROBE_ULPS ulps of float64 and timed again. Per swing: ``timed_tie`` whether
    any probe changed its sample count or its within-limits verdict (a discrete outcome at a tie),
    else the largest change of its duration (s) and of its joint angles (rad) over the probes."""
    from jaxexo.inference import time_swings

    rng = np.random.default_rng(PROBE_SEED)
    n = len(timed)
    tie, duration, angles = np.zeros(n, bool), np.zeros(n), np.zeros(n)
    for k in PROBE_ULPS:
        probed = [_probe(t, k, rng) for t in trajs]
        for i, (a, b) in enumerate(zip(timed, time_swings(probed, config))):
            if len(a.time) != len(b.time) or a.ok != b.ok:
                tie[i] = True
                continue
            duration[i] = max(duration[i], abs(a.duration - b.duration))
            angles[i] = max(angles[i], float(np.abs(a.joint_angles - b.joint_angles).max()))
    return {"timed_tie": tie, "timed_duration_probe": duration, "timed_angles_probe": angles}


def outputs(policy: Path = POLICY, sensitivity: dict | None = None) -> dict[str, np.ndarray]:
    """Every stored array, keyed "<generator>/<set>/<field>"; ``sensitivity`` (a dict) is filled
    with each set's timing_sensitivity, keyed the same way."""
    rl = TrajectoryGenerator.load(policy)
    generators = {"rl": rl, "cfftg": CFFTG.from_policy(policy)}
    out = {}
    for set_name, (scenes, options) in scene_sets(rl.config).items():
        obstacles = [s.obstacle for s in scenes]
        for gen_name, gen in generators.items():
            batch = gen.generate_batch(obstacles, options, **batch_options(scenes))
            key = f"{gen_name}/{set_name}"
            out[f"{key}/heel"] = np.asarray(batch.heel, np.float32)
            methods = batch.row_methods or (batch.method,) * len(batch)
            margin = (
                gen.config.env.min_clearance if options.clearance is None else options.clearance
            )
            out[f"{key}/margin"] = np.float64(margin)  # what clearance_ok judges against
            out[f"{key}/method"] = np.asarray(methods, dtype="U32")
            out[f"{key}/reasons"] = np.asarray(["; ".join(r) for r in batch.reasons])
            for name in FLAGS:
                out[f"{key}/{name}"] = np.asarray(getattr(batch, name), bool)
            for name in NUMBERS:
                out[f"{key}/{name}"] = np.asarray(getattr(batch, name), np.float64)
            swings = [batch[i] for i in range(TIMED_PER_SET)]
            timed = time_swings(swings, gen.config)
            if sensitivity is not None:
                for name, value in timing_sensitivity(swings, timed, gen.config).items():
                    sensitivity[f"{key}/{name}"] = value
            out[f"{key}/timed_ok"] = np.array([t.ok for t in timed])
            out[f"{key}/timed_duration"] = np.array([t.duration for t in timed])
            out[f"{key}/timed_samples"] = np.array([len(t.time) for t in timed])
            out[f"{key}/timed_joint_angles"] = np.concatenate(
                [t.joint_angles for t in timed]
            ).astype(np.float32)
    return out


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        sys.exit(f"usage: python tests/reference_outputs.py --write  (rewrites {STORED})")
    np.savez_compressed(STORED, **outputs())
    print(f"wrote {STORED} ({STORED.stat().st_size / 1e6:.2f} MB)")
