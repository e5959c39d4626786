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
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.benchmarks.scenes import batch_kwargs, safety_sets
from jaxexo.inference import GenerateOptions, TrajectoryGenerator, time_swings
from jaxexo.inference.scenarios import training_scenarios

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


def outputs(policy: Path = POLICY) -> dict[str, np.ndarray]:
    """Every stored array, keyed "<generator>/<set>/<field>"."""
    rl = TrajectoryGenerator.load(policy)
    generators = {"rl": rl, "cfftg": CFFTG.from_policy(policy)}
    out = {}
    for set_name, (scenes, options) in scene_sets(rl.config).items():
        obstacles = [s["obstacle"] for s in scenes]
        for gen_name, gen in generators.items():
            batch = gen.generate_batch(obstacles, options, **batch_kwargs(scenes))
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
            timed = time_swings([batch[i] for i in range(TIMED_PER_SET)], gen.config)
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
