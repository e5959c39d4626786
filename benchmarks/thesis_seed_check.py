"""Evidence: the thesis learns configs trained by ``jaxexo train`` (the driver ``jaxexo reproduce``
uses: model selection on validation layouts, the best chunk exported) with several seeds, so that a
target met or missed by ``jaxexo reproduce``'s seed 0 is not read as a property of the config.

Each row: one run directory's eval.json (greedy JAX rollouts of the exported policy on the 1000 test
layouts: strict success of the raw moves, eq 3.1 accuracy, goal reached, held-out triangle and
half-circle), the chunk selected, the training time. Writes benchmarks/results/thesis-seeds_<date>_<machine>.{json,md}.

Run: python benchmarks/thesis_seed_check.py NOTE MODEL=RUN_DIR:SEED [MODEL=RUN_DIR:SEED ...]"""

import json
import sys
from pathlib import Path

from jaxexo.evaluation.machine import write_result


def main(note: str, runs: list[str]) -> None:
    head = ("| config | seed | strict success % | accuracy % (eq 3.1) | reached goal % | held-out success % | "
            "selected chunk | train s |")
    lines = ["# Thesis learns configs over seeds (jaxexo train, the reproduce driver)", "", note, "",
             "Command per row: `jaxexo train jaxexo/config/thesis/<config>.toml --out DIR --seed S` (seed 0: the "
             "run of `jaxexo reproduce --variant both`). Scores: the run's eval.json, greedy JAX rollouts of the "
             "exported (best validated) policy on the 1000 test layouts (five thesis obstacles x three pivot "
             "conditions), raw moves, no smoothing.", "", head, "|---|---:|---:|---:|---:|---:|---:|---:|"]
    rows = []
    for spec in runs:
        model, rest = spec.split("=", 1)
        run, seed = rest.rsplit(":", 1)
        ev = json.loads((Path(run) / "eval.json").read_text())
        row = {"config": model, "seed": int(seed), "success": ev["success_raw"],
               "accuracy": ev["accuracy"], "reached_goal": ev["reached_goal"],
               "held_out_success": ev["held_out"]["success_raw"],
               "selected_chunk": ev.get("selected_chunk"), "train_seconds": ev["train_seconds"]}
        rows.append(row)
        lines.append(f"| {model} | {seed} | {100 * row['success']:.1f} | {100 * row['accuracy']:.1f} | "
                     f"{100 * row['reached_goal']:.1f} | {100 * row['held_out_success']:.1f} | "
                     f"{row['selected_chunk']} | {row['train_seconds']:.1f} |")
    for p in write_result("thesis-seeds", {"note": note, "rows": rows}, "\n".join(lines),
                          Path(__file__).resolve().parent / "results"):
        print(p)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
