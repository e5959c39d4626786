"""The scene sets the swing benchmarks share: the thesis five with shifted layouts, shapes never
trained on (both jaxexo.inference.scenarios.safety_scenarios) and the held-out terrain families
(jaxexo.physics.scenarios.unseen_scenarios), and the Markdown table of figures per scene set and generator."""

from __future__ import annotations

import numpy as np

from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import scenarios
from jaxexo.summary import table

THESIS_FIVE, SHAPES, FAMILIES = "thesis five, shifted", "unseen shapes", "held-out families"


def held_out_families(config, n: int, pick: bool = True) -> list[scenarios.Scenario]:
    """The held-out families in whole cells of at least ``n`` scenes; with ``pick``, ``n`` of them
    drawn at random (seed 0, kept in order)."""
    fam = scenarios.unseen_scenarios(
        config.kinematics.foot_length, repeats=scenarios.repeats_for(n)
    )
    if not pick:
        return fam
    rng = np.random.default_rng(0)
    return [fam[i] for i in np.sort(rng.choice(len(fam), size=min(n, len(fam)), replace=False))]


def safety_sets(
    config, n: int, shapes_seed: int = 2024, pick: bool = True
) -> dict[str, list[scenarios.Scenario]]:
    """The three sets by name: ``n`` scenes of the thesis five and of unseen shapes (drawn with
    ``shapes_seed``), and the held-out families (see held_out_families)."""
    return {
        THESIS_FIVE: safety_scenarios(config, n),
        SHAPES: safety_scenarios(config, n, seed=shapes_seed, unseen=True),
        FAMILIES: held_out_families(config, n, pick),
    }


def set_table(columns, sets: dict, cells) -> list[str]:
    """A Markdown table of a row per scene set and generator of ``sets`` ({set: {generator: figures}}):
    the columns set, generator and ``columns`` (right-aligned), ``cells(figures)`` the row's cells after
    the first two, as text ("a | b")."""
    rows = [(s, g, cells(r)) for s, gens in sets.items() for g, r in gens.items()]
    return table(("set", "generator", *columns), rows, "ll" + "r" * len(columns))
