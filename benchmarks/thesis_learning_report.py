"""Evidence: why the faithful thesis configs do not learn, and which switches make them learn.

Turns finished ``jaxexo sweep`` directories (configs/sweeps/thesis_*.toml) into one result per study
(benchlib.thesis_reports.learning_report),
benchmarks/results/thesis-learning-<study>_<date>_<machine>.{json,md}: the sweep file, the command, every
agent's row (greedy strict success and eq 3.1 accuracy on the 1000 thesis test layouts, held-out success,
behaviour-policy success over the last tenth of training, episodes, updates, wall time) and the mean
over seeds per configuration.

Run: python benchmarks/thesis_learning_report.py STUDY SWEEP_FILE SWEEP_DIR [NOTE]"""

from pathlib import Path

from benchlib.runner import parser
from benchlib.thesis_reports import learning_report

if __name__ == "__main__":
    p = parser(__doc__, policy=False)
    for arg in ("study", "sweep_file", "sweep_dir"):
        p.add_argument(arg)
    p.add_argument("note", nargs="?", default="")
    a = p.parse_args()
    learning_report(
        a.study, a.sweep_file, a.sweep_dir, Path(__file__).resolve().parent / "results", a.note
    )
