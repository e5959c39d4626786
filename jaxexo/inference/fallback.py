"""The fallback composition: the RL generator's swings, with another generator's swing (its
``fallback_generator``'s: CFFTG's plan or continuation) wherever the RL one fails the safe-swing
check and the other's passes; its notes keep both failures.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from jaxexo.swing.trajectory import TrajectoryBatch


def replace_failures(batch: TrajectoryBatch, planner, label: str) -> TrajectoryBatch:
    """``batch`` with each failing row replaced by the swing ``planner(scenes)`` (a TrajectoryBatch,
    one row per scene) plans for its scene where that passes, its method ``label``."""
    bad = np.flatnonzero(~batch.ok)
    if not bad.size:
        return batch
    plan = planner([batch.scenes[i] for i in bad])
    take = [j for j in range(len(bad)) if plan.ok[j]]
    notes = list(batch.notes)
    for j, i in enumerate(bad):
        rl_fail = "RL swing failed the safe-swing check: " + "; ".join(batch.reasons[i])
        notes[i] = notes[i] + (
            (rl_fail + "; CFFTG's plan is returned",)
            if j in take
            else (rl_fail, "CFFTG fallback failed too: " + "; ".join(plan.reasons[j]))
        )
    batch = dataclasses.replace(batch, notes=tuple(notes))
    if not take:
        return batch
    sub = dataclasses.replace(plan, method=label, row_methods=()).take(take)
    sub = dataclasses.replace(
        sub, notes=tuple(notes[bad[j]] + sub.notes[n] for n, j in enumerate(take))
    )
    return batch.with_rows([bad[j] for j in take], sub)
