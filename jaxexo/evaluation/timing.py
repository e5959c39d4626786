"""Timing of the NumPy generators: seconds per ``generate`` call and per ``generate_batch``, used by
``jaxexo eval`` and the generator benchmark alike."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from jaxexo.physics.scenarios import Scenario, batch_options

if TYPE_CHECKING:
    from jaxexo.inference import TrajectoryGenerator

BATCH = 1000  # scenarios per timed generate_batch (thesis Table 3.11 times 1000)


def time_batch(gen: TrajectoryGenerator, scenarios: list[Scenario], repeats: int = 5, **options):
    """Seconds per ``generate_batch`` of all scenarios (one per repeat), and the last batch;
    ``options`` go to generate_batch (e.g. ``fallback=None``)."""
    obstacles, per_scene = [s.obstacle for s in scenarios], batch_options(scenarios)
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        batch = gen.generate_batch(obstacles, **per_scene, **options)
        out.append(time.perf_counter() - t0)
    return out, batch
