"""The shield: the moves the agent may choose from a heel, its rule once and its three forms.

``rule`` states the rule once for every array module (``admissible_moves`` and its pieces). Three
forms compute it where it is needed, with the same decisions bit for bit, behind one interface
chosen at construction, ``make_shield(kind, p, sp, stats)``:

- ``"jax"`` (``batched.BatchedShield``): the trainer's mask of N environments in JAX, the exact
  swept clearance only for the moves a cheap bound leaves open (``compact``);
- ``"rows"`` (``rows.ShieldRows``): many heels in NumPy float32, the generator's batches;
- ``"scalar"`` (``scalar.ScalarShield``): one heel at a time in Python floats, checking only the
  move that will be taken, the generator's single swing (``.swing(scene)``).

Each has ``admissible(heel_y, heel_z, layout, last_action=None)``, (B, NUM_ACTIONS) bool for heels
(B,) in stacked scenes (``layout``: the Layout fields with a leading B), ``choose(heel_y, heel_z,
layout, q, last_action)``, the greedy move among them for Q-values (B, NUM_ACTIONS), and ``stats``, the
``ShieldStats`` record of its choices. ``import jaxexo.shield`` imports NumPy only; the JAX form is
imported when it is chosen.
"""

from __future__ import annotations

from jaxexo.shield.rows import ShieldStats

KINDS = ("jax", "rows", "scalar")


def make_shield(kind: str, p, sp=None, stats: ShieldStats | None = None, **options):
    """The shield's form ``kind`` (one of KINDS) for parameters ``p`` (EnvParams for ``"jax"``,
    jaxexo.config.numpy_params for the NumPy forms) and ``sp`` (jaxexo.config.scalar_params, for the
    NumPy forms), counting its choices in ``stats`` (None: a fresh ShieldStats). ``options``: the JAX
    form's ``buffer`` (open pairs checked exactly per round)."""
    if kind == "jax":
        from jaxexo.shield.batched import BatchedShield

        return BatchedShield(p, sp, stats, **options)
    if options:
        raise TypeError(f"make_shield({kind!r}): unexpected options {sorted(options)}")
    if sp is None:
        raise TypeError(f"make_shield({kind!r}): the scalar parameters sp are needed")
    if kind == "rows":
        from jaxexo.shield.rows import ShieldRows

        return ShieldRows(p, sp, stats)
    if kind == "scalar":
        from jaxexo.shield.scalar import ScalarShield

        return ScalarShield(p, sp, stats)
    raise ValueError(f"shield kind must be one of {KINDS}, got {kind!r}")


__all__ = ["KINDS", "ShieldStats", "make_shield"]
