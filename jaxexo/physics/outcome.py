"""The one verdict on a swing: did it succeed, and if not, which checks failed.

Every success figure in jaxexo comes from here (training curve, evaluation, baselines, checked
trajectories), written for the array module ``xp``. ``verdict`` judges finished paths from their
aggregates; ``start`` / ``accumulate`` / ``episode_verdict`` fold an episode's per-step flags. The
rule's two parameters (``env.min_clearance``, ``env.backward_tolerance``) have their defaults here.
What a safe swing is: docs/safety.md#a-safe-swing-the-trajectory-checks.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from jaxexo.physics import geometry

# m: the clearance a safe swing keeps from the obstacle outline (config env.min_clearance).
DEFAULT_MIN_CLEARANCE = 0.02
# m: how far the heel may fall back behind its furthest y so far (config env.backward_tolerance).
DEFAULT_BACKWARD_TOLERANCE = 0.005

# The checks, in the order their reasons are reported.
CHECKS = (
    "reached_goal",
    "clearance_ok",
    "above_ground",
    "backward_ok",
    "joint_limits_ok",
    "leg_length_ok",
)


class Verdict(NamedTuple):
    """The verdict on swings, every flag a bool array of the swings' shape (a NamedTuple, so a pytree
    for JAX without importing it). ``collision_free``: eq 3.1, never touched whatever the margin;
    ``success``: every check of CHECKS holds."""

    success: Any
    collision_free: Any
    reached_goal: Any
    clearance_ok: Any
    above_ground: Any
    backward_ok: Any
    joint_limits_ok: Any
    leg_length_ok: Any


def rule(p) -> dict:
    """The rule parameters of ``verdict`` from environment parameters ``p`` (EnvParams, or any object
    with ``min_clearance`` and ``backward_tolerance``, m)."""
    return {"min_clearance_margin": p.min_clearance, "backward_tolerance": p.backward_tolerance}


def verdict(
    xp,
    reached_goal,
    min_clearance,
    joint_limits_ok,
    leg_length_ok,
    max_backward,
    above_ground=True,
    *,
    min_clearance_margin=DEFAULT_MIN_CLEARANCE,
    backward_tolerance=DEFAULT_BACKWARD_TOLERANCE,
) -> Verdict:
    """The verdict on whole swings from their aggregates (any shape, broadcast together).

    ``min_clearance`` (m) the smallest clearance of the foot's motion from the obstacle (for a sampled
    path: guaranteed between the samples); ``max_backward`` (m) the largest fall of the heel behind its
    furthest y so far; ``above_ground`` whether the heel stayed at z >= 0. Returns the flags of
    CHECKS, ``collision_free`` (eq 3.1: never touched, whatever the margin) and ``success`` (all
    CHECKS hold; a margin >= 0 implies collision_free)."""
    collision_free = ~geometry.foot_collides(xp, min_clearance)
    clearance_ok = collision_free & ~geometry.foot_collides(
        xp, min_clearance - min_clearance_margin
    )
    backward_ok = max_backward <= backward_tolerance
    above_ground = xp.ones_like(collision_free) & above_ground
    success = (
        reached_goal & clearance_ok & above_ground & backward_ok & joint_limits_ok & leg_length_ok
    )
    return Verdict(
        success=success,
        collision_free=collision_free,
        reached_goal=reached_goal,
        clearance_ok=clearance_ok,
        above_ground=above_ground,
        backward_ok=backward_ok,
        joint_limits_ok=joint_limits_ok,
        leg_length_ok=leg_length_ok,
    )


class Running(NamedTuple):
    """An episode's running aggregates ``[...]`` (the batch of episodes), folded by ``accumulate``."""

    reached_goal: Any  # [...] bool
    limits: Any  # [...] bool: a joint limit was violated
    leg: Any  # [...] bool: a leg was too long
    min_clearance: Any  # [...] m, the smallest clearance of the foot's motion
    max_backward: Any  # [...] m, the largest fall of the heel behind its furthest y


def start(xp, shape=(), dtype="float32") -> Running:
    """An episode's running aggregates before its first step (``shape``: the batch of episodes)."""
    no = xp.zeros(shape, dtype=bool)
    inf, zero = xp.full(shape, xp.inf, dtype=dtype), xp.zeros(shape, dtype=dtype)
    return Running(reached_goal=no, limits=no, leg=no, min_clearance=inf, max_backward=zero)


def accumulate(xp, acc: Running, info, alive=True) -> Running:
    """Fold one environment step's ``info`` (jaxexo.physics.transition.StepInfo) into ``acc``;
    steps where ``alive`` is False (after the episode ended) leave it unchanged."""
    return Running(
        reached_goal=acc.reached_goal | (alive & info.goal_reached),
        limits=acc.limits | (alive & info.joint_limit_violation),
        leg=acc.leg | (alive & info.leg_length_violation),
        min_clearance=xp.where(
            alive, xp.minimum(acc.min_clearance, info.clearance), acc.min_clearance
        ),
        # info.backward: how far the heel is behind its furthest y so far (the step's running max)
        max_backward=xp.where(alive, xp.maximum(acc.max_backward, info.backward), acc.max_backward),
    )


def episode_verdict(xp, acc: Running, **rule) -> Verdict:
    """The verdict on episodes from their running aggregates (``accumulate``)."""
    return verdict(
        xp, acc.reached_goal, acc.min_clearance, ~acc.limits, ~acc.leg, acc.max_backward, **rule
    )


def failed_checks(v, i=None) -> tuple[str, ...]:
    """Names (CHECKS) of the checks failed by ``v`` (a Verdict, or any record with the CHECKS as
    fields), for swing ``i`` of a batch (NumPy values)."""
    pick = (lambda x: x) if i is None else (lambda x: x[i])
    return tuple(c for c in CHECKS if not bool(pick(getattr(v, c))))
