"""Evidence: why the faithful thesis configs do not learn, and which switches make them learn.

Turns finished ``jaxexo sweep`` directories (configs/sweeps/thesis_*.toml) into one result per study,
benchmarks/results/thesis-learning-<study>_<date>_<machine>.{json,md}: the sweep file, the command, every
agent's row (greedy strict success and eq 3.1 accuracy on the 1000 thesis test layouts, held-out success,
behaviour-policy success over the last tenth of training, episodes, updates, wall time) and the mean
over seeds per configuration.

Run: python benchmarks/thesis_learning_report.py STUDY SWEEP_FILE SWEEP_DIR [NOTE]"""

import csv
import json
import sys
from collections import defaultdict
from pathlib import Path

from jaxexo.evaluation.machine import write_result

COLS = ("success", "accuracy", "held_out_success", "train_success", "eval_return", "episodes", "updates", "wall_s")
PCT = {"success", "accuracy", "held_out_success", "train_success"}


def _fmt(col: str, v: str) -> str:
    if v in ("", "nan"):
        return "-"
    x = float(v)
    return f"{100 * x:.1f}" if col in PCT else (f"{x:.0f}" if col in ("episodes", "updates") else f"{x:.2f}")


def report(study: str, sweep_file: str, sweep_dir: str, note: str = "") -> None:
    sweep = json.loads((Path(sweep_dir) / "sweep.json").read_text())
    axes = list(sweep.get("sweep", {}).get("grid", {}))
    rows = list(csv.DictReader(open(Path(sweep_dir) / "results.csv")))
    head = "| " + " | ".join([*axes, "seed", "strict success %", "accuracy % (eq 3.1)", "held-out success %",
                              "train success % (last 10 %)", "greedy return", "episodes", "updates", "wall s"]) + " |"
    align = "|" + "---|" * (len(axes) + 1) + "---:|" * len(COLS)
    lines = [f"# Thesis learning study: {study}", "", note, "",
             f"Command: `jaxexo sweep {sweep_file} --out DIR` (then `python benchmarks/thesis_learning_report.py "
             f"{study} {sweep_file} DIR`). Scores: greedy rollouts on 1000 test layouts (the five thesis obstacles "
             "x three pivot conditions; triangle and half-circle never trained on). Wall s: the compiled group "
             "the agent ran in, all its agents together, on this machine (busy, shared by other jobs).", "",
             "## Per configuration (mean over seeds)", "", head.replace("| seed ", "| seeds "), align]
    groups = defaultdict(list)
    for r in rows:
        groups[tuple(r[a] for a in axes)].append(r)
    for key, rs in groups.items():
        means = [str(sum(float(r[c]) for r in rs) / len(rs)) if all(r[c] not in ("", "nan") for r in rs) else "nan"
                 for c in COLS]
        lines.append("| " + " | ".join([*key, str(len(rs)), *(_fmt(c, m) for c, m in zip(COLS, means))]) + " |")
    lines += ["", "## Every agent", "", head, align]
    for r in rows:
        lines.append("| " + " | ".join([*(r[a] for a in axes), r["seed"], *(_fmt(c, r[c]) for c in COLS)]) + " |")
    payload = {"study": study, "sweep_file": sweep_file, "axes": axes, "note": note,
               "rows": [{k: r[k] for k in (*axes, "seed", *COLS)} for r in rows]}
    for p in write_result(f"thesis-learning-{study}", payload, "\n".join(lines),
                          Path(__file__).resolve().parent / "results"):
        print(p)


if __name__ == "__main__":
    report(*sys.argv[1:5])
