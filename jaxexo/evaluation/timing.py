"""Timing of the NumPy generators: seconds per ``generate`` call and per ``generate_batch``, used by
``jaxexo eval`` and the generator benchmark alike."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from jaxexo.inference import TrajectoryGenerator

BATCH = 1000  # scenarios per timed generate_batch (thesis Table 3.11 times 1000)


def scene_options(s: dict) -> dict:
    """``generate``'s keyword arguments of a scenario dict (jaxexo.inference.scenarios)."""
    return {"pivot": s["pivot"], "start_y": s["start_y"], "step_length": s["step_length"]}


def time_batch(gen: TrajectoryGenerator, scenarios: list[dict], repeats: int = 5, **options):
    """Seconds per ``generate_batch`` of all scenarios (one per repeat), and the last batch;
    ``options`` go to generate_batch (e.g. ``fallback=None``)."""
    args = {k: [s[k] for s in scenarios] for k in ("obstacle", "pivot", "start_y", "step_length")}
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        batch = gen.generate_batch(
            args["obstacle"],
            pivot=args["pivot"],
            start_y=args["start_y"],
            step_length=args["step_length"],
            **options,
        )
        out.append(time.perf_counter() - t0)
    return out, batch
