"""The public held-out benchmark's report: fixed scenes of obstacle families no training draws, run
by both generators (``jaxexo eval --scenarios unseen``), per family and generator. The seed is fixed
so that numbers compare between models; do not tune a model to it. Method:
docs/generation.md#jaxexo-eval-both-generators-side-by-side."""

from __future__ import annotations

import numpy as np

from jaxexo.evaluation.metrics import path_length
from jaxexo.physics.scenarios import Scenario
from jaxexo.summary import Summary
from jaxexo.summary import table as md_table


def family_table(trajs: dict, scenarios: list[Scenario]) -> dict:
    """Per family and generator: n, success, accuracy, clearance min/p5/median (m), path length
    mean/median (m). ``trajs``: {generator: [Trajectory per scenario]}."""
    kinds = np.array([s.kind for s in scenarios])
    table = {}
    for fam in dict.fromkeys(kinds):
        mask = kinds == fam
        table[fam] = {}
        for name, tr in trajs.items():
            sel = [t for t, m in zip(tr, mask) if m]
            clr = Summary.of(np.array([t.checks.min_clearance for t in sel], dtype=np.float64))
            pl = Summary.of(np.array([path_length(t.heel) for t in sel]))
            table[fam][name] = {
                "n": len(sel),
                "success": float(np.mean([t.ok for t in sel])),
                "accuracy": float(np.mean([t.checks.collision_free for t in sel])),
                "clearance_m_min": clr.min,
                "clearance_m_p5": clr.p5,
                "clearance_m_median": clr.median,
                "path_length_m_mean": pl.mean,
                "path_length_m_median": pl.median,
            }
    return table


def family_cells(r: dict) -> tuple[str, ...]:
    """One family's row of figures (``family_table``'s entry) after its labels: n, success %, accuracy
    %, clearance min, p5 and median cm, path length mean cm."""
    return (
        str(r["n"]),
        *(f"{100 * r[k]:.1f}" for k in ("success", "accuracy")),
        *(f"{100 * r[k]:.2f}" for k in ("clearance_m_min", "clearance_m_p5", "clearance_m_median")),
        f"{100 * r['path_length_m_mean']:.1f}",
    )


def markdown_lines(table: dict) -> list[str]:
    """The per-family table as Markdown lines (clearance and path length in cm, labelled; the path
    length's median is in the report's JSON)."""
    header = ("family (generator)", "n", "safe swing (strict success) %", "accuracy %")
    header += ("clearance min cm", "p5 cm", "median cm", "path length mean cm")
    rows = [(f"{f} ({g})", *family_cells(r)) for f, gens in table.items() for g, r in gens.items()]
    return [
        "## Unseen families (held out from training by construction)",
        "",
        *md_table(header, rows),
    ]
