"""The thesis's published results, read once from ``thesis_results.toml`` (shipped beside this
module): the one copy of the numbers that ``jaxexo reproduce`` tabulates and ``jaxexo eval`` quotes
beside jaxexo's own. Units as the thesis prints them: ms, degrees, per cent. NumPy-free."""

from __future__ import annotations

import tomllib
from pathlib import Path

_DATA = tomllib.loads(
    (Path(__file__).resolve().parent / "thesis_results.toml").read_text(encoding="utf-8")
)

# Tables 3.2 / 3.9: model -> (mean generation time ms, mean swing knee deg, mean swing hip deg).
THESIS_T32 = {model: tuple(v) for model, v in _DATA["generation"].items()}
# Tables 3.3-3.8: model -> {pivot condition not trained on: the same three figures}.
THESIS_CROSS = {
    model: {pivot: tuple(v) for pivot, v in row.items()}
    for model, row in _DATA["cross_pivot"].items()
}
THESIS_ACCURACY = dict(_DATA["accuracy"])  # Table 3.10: model -> accuracy (eq 3.1), %
THESIS_TRAIN_TIME = dict(
    _DATA["training_time"]
)  # model -> training time on the thesis's laptop, as printed
# Table 3.11: obstacle kind -> (CFFTG ms, final model ms).
THESIS_T311 = {kind: tuple(v) for kind, v in _DATA["per_obstacle"].items()}
THESIS_BATCH_1000_MS = _DATA["final_model"][
    "batch_1000_ms"
]  # the final model's 1000 test trajectories, ms
THESIS_CFFTG_MS = _DATA["final_model"]["cfftg_ms"]  # CFFTG's time per trajectory, ms (about)
