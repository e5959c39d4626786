"""Replanned swings driven through the switch (benchlib.replan_replay_bench): surprise
scenes of shapes never trained on (poles, stairs, bumps, smooth bumps; the true obstacle 30-60 %
taller than estimated, or 3-5 cm from where it was estimated, known at 15-40 % of the swing), a
swing planned and timed over the estimate and replanned over the true obstacle by the policy
(alone) and by CFFTG, then driven in MuJoCo in the true scene from the start, following the old
swing until the switch and the replanned one after: within the margin, contacts, clipped
setpoints, heel error, the commanded acceleration's jump across the switch; and the old swing left
alone in the true scene.

Writes benchmarks/results/<name>_<date>_<machine>.{json,md} (default name replan-replay).

Run: python benchmarks/bench_replan_replay.py RUN_DIR/policy.npz [--n 200] [--seed 59]
     [--clearance M] [--name NAME]
"""

from pathlib import Path

from benchlib.replan_replay_bench import run_replan_replay_benchmark
from benchlib.runner import run_script

if __name__ == "__main__":
    run_script(
        __doc__,
        run_replan_replay_benchmark,
        [
            ("--n", "n", "surprise scenes (each generator replans on all)"),
            ("--seed", "seed", "the scenes' seed"),
            ("--name", "name", "the results' file name before the date"),
            ("--clearance", "clearance", "m the replans keep (0: the config's margin)"),
        ],
        Path(__file__).resolve().parent / "results",
    )
