"""The shield: the moves the agent may choose from a heel. ``rule`` states it once for every array
module; ``make_shield(kind, p, sp, stats)`` picks one of its three forms with the same decisions:
``"jax"`` (``batched``, the trainer's mask), ``"rows"`` (``rows``, the generator's NumPy batches) and
``"scalar"`` (``scalar``, one heel, only the move taken), each with ``admissible``, ``choose`` and
``stats``. NumPy only until the JAX form is chosen. See docs/safety.md and docs/architecture.md.
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
