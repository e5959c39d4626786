"""The public held-out benchmark: fixed scenes of obstacle families that no training draws.

Scenes are the held-out families of jaxexo.physics.terrain (pole, stairs, curb, bumps, smooth_bump:
excluded from training by construction, see that module) crossed with the three pivot conditions,
three agent starts (0, 6 and 12 cm closer to the obstacle) and three step lengths (the shortest that
fits the drawn obstacle, the middle and the longest of 0.55-0.85 m), each cell drawn ``repeats``
times: the shape and the obstacle's position in the gap from NumPy Generators seeded with the fixed
``UNSEEN_SEED``. Every scene is a keyword dict of ``generate`` (the RL TrajectoryGenerator and CFFTG
accept the same), so both generators run on identical scenes (``jaxexo eval --scenarios unseen``).

The report per family and generator: strict success rate (goal reached, never touching the
obstacle, joint limits and leg length; "safe swing"), accuracy (eq 3.1), the trajectory's minimum
clearance over the family's scenes (min, 5th percentile, median, m) and the heel path length (m).
The seed is fixed so that numbers are comparable between models; do not tune a model to it.
"""

from __future__ import annotations

import math

import numpy as np

from jaxexo.evaluation.metrics import path_length
from jaxexo.physics import terrain
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

UNSEEN_SEED = 20_261_122
START_SHIFT = (0.0, 0.12)      # m, the agent starts up to 12 cm closer to the obstacle
STEP_LENGTH = (0.55, 0.85)     # m
LEVELS = (0.0, 0.5, 1.0)       # fractions of the start and step-length ranges
CELLS_PER_FAMILY = len(PIVOT_CONDITIONS) * len(LEVELS) * len(LEVELS)


def repeats_for(n: int, families=terrain.HELD_OUT_FAMILIES) -> int:
    """Draws per (family, pivot, start, step length) cell so that the set has at least n scenes."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    return max(1, math.ceil(n / (len(families) * CELLS_PER_FAMILY)))


def unseen_scenarios(foot_length: float, repeats: int = 2, seed: int = UNSEEN_SEED,
                     families=terrain.HELD_OUT_FAMILIES) -> list[dict]:
    """The held-out scene set: families x pivots x starts x step lengths x ``repeats`` draws (shape
    and position), as dicts of ``generate``'s keyword arguments plus ``kind`` (the family name) and
    ``family_u`` (the shape's uniform numbers, for reproducing it with terrain.family_outline)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    for f in families:
        terrain.family_id(f)   # names the bad family
    out = []
    for fi, fam in enumerate(families):
        # One Generator per family: adding a family never changes another family's scenes.
        rng = np.random.default_rng([seed, fi])
        n = CELLS_PER_FAMILY * repeats
        u_shape, u_place = terrain.draw_uniforms(rng, n)
        outline, width, _ = terrain.one_family_outline(np, fam, u_shape.astype(np.float64))
        i = 0
        for pk, pivot in enumerate(PIVOT_CONDITIONS):
            for a in LEVELS:
                for b in LEVELS:
                    for _ in range(repeats):
                        u = np.array([a, b, u_place[i, 2]], dtype=np.float64)
                        start, L, c = terrain.place(np, u, width[i], START_SHIFT, STEP_LENGTH, foot_length)
                        out.append({"kind": fam, "obstacle": terrain.to_obstacle(outline[i], float(c)),
                                    "pivot": pivot, "start_y": float(start), "step_length": float(L),
                                    "family_u": u_shape[i].tolist()})
                        i += 1
    return out


def family_table(trajs: dict, scenarios: list[dict]) -> dict:
    """Per family and generator: n, success, accuracy, clearance min/p5/median (m), path length
    mean/median (m). ``trajs``: {generator: [Trajectory per scenario]}."""
    kinds = np.array([s["kind"] for s in scenarios])
    table = {}
    for fam in dict.fromkeys(kinds):
        mask = kinds == fam
        table[fam] = {}
        for name, tr in trajs.items():
            sel = [t for t, m in zip(tr, mask) if m]
            clr = np.array([t.checks.min_clearance for t in sel], dtype=np.float64)
            pl = np.array([path_length(t.heel) for t in sel])
            table[fam][name] = {
                "n": len(sel),
                "success": float(np.mean([t.ok for t in sel])),
                "accuracy": float(np.mean([t.checks.collision_free for t in sel])),
                "clearance_m_min": float(np.min(clr)),
                "clearance_m_p5": float(np.percentile(clr, 5)),
                "clearance_m_median": float(np.median(clr)),
                "path_length_m_mean": float(pl.mean()),
                "path_length_m_median": float(np.median(pl)),
            }
    return table


def markdown_lines(table: dict) -> list[str]:
    """The per-family table as Markdown lines (clearance and path length in cm, labelled)."""
    lines = ["## Unseen families (held out from training by construction)", "",
             "| family | generator | n | safe-swing (strict success) % | accuracy % | clearance min cm | "
             "p5 cm | median cm | path length mean cm | median cm |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for fam, gens in table.items():
        for name, r in gens.items():
            lines.append(f"| {fam} | {name} | {r['n']} | {100 * r['success']:.1f} | {100 * r['accuracy']:.1f} | "
                         f"{100 * r['clearance_m_min']:.2f} | {100 * r['clearance_m_p5']:.2f} | "
                         f"{100 * r['clearance_m_median']:.2f} | {100 * r['path_length_m_mean']:.1f} | "
                         f"{100 * r['path_length_m_median']:.1f} |")
    return lines
