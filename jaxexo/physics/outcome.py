"""The one verdict on a swing: did it succeed, and if not, which checks failed.

Every success figure in jaxexo comes from ``verdict``: the training curve (jaxexo.train.trainer),
greedy evaluation and validation (jaxexo.train.evaluate, eval.json, sweeps), the thesis-style
baseline's NumPy environment, CFFTG's planning loop and the checked trajectories
(jaxexo.inference.trajectory, ``jaxexo eval``). Written against the array module ``xp`` (numpy,
jax.numpy) like the rest of jaxexo.physics, so the JAX environment's episode flags and the NumPy
trajectory samples are judged by the same code.

Strict success (thesis 3.3, eq 3.1 extended): the heel reached the goal (eq 2.32's goal), the heel-toe
segment kept at least ``min_clearance`` from the obstacle (eq 2.30 with the foot's length; 0 m: it
never touched), both legs stayed inside their joint limits (eq 2.50) and no leg had to stretch beyond
thigh + shin (eq 2.45), and the heel never moved backwards by more than ``backward_tolerance``
(eq 2.31's condition; not checked by default). Accuracy (eq 3.1) is ``collision_free``: never touched.

The two rule parameters have today's behaviour as defaults (DEFAULT_MIN_CLEARANCE,
DEFAULT_BACKWARD_TOLERANCE); tightening what a safe swing is changes those two constants only.

Two ways in: ``from_samples`` reduces per-sample arrays (..., N) of a finished path; ``start`` /
``accumulate`` / ``episode_verdict`` fold per-step flags of an environment episode as it runs.
"""

from __future__ import annotations

import math

from jaxexo.physics import geometry

# m: the clearance a successful swing keeps from the obstacle (0: it must not touch, eq 3.1).
DEFAULT_MIN_CLEARANCE = 0.0
# m: how far the heel may move backwards in one step or between two samples (inf: not checked).
DEFAULT_BACKWARD_TOLERANCE = math.inf

# The checks, in the order their reasons are reported.
CHECKS = ("reached_goal", "clearance_ok", "joint_limits_ok", "leg_length_ok", "backward_ok")


def verdict(xp, reached_goal, min_clearance, joint_limits_ok, leg_length_ok, max_backward=None, *,
            min_clearance_margin: float = DEFAULT_MIN_CLEARANCE,
            backward_tolerance: float = DEFAULT_BACKWARD_TOLERANCE) -> dict:
    """The verdict on whole swings from their aggregates (any shape, broadcast together).

    ``min_clearance`` (m) the smallest foot-obstacle clearance over the swing; ``max_backward`` (m)
    the largest backward heel move (None: not measured, only allowed with an infinite tolerance).
    Returns the flags of CHECKS, ``collision_free`` (eq 3.1: never touched, whatever the margin) and
    ``success`` (all CHECKS hold)."""
    collision_free = ~geometry.foot_collides(xp, min_clearance)
    clearance_ok = ~geometry.foot_collides(xp, min_clearance - min_clearance_margin)
    if math.isinf(backward_tolerance):
        backward_ok = xp.ones_like(collision_free)
    elif max_backward is None:
        raise ValueError("verdict: a finite backward_tolerance needs max_backward (m)")
    else:
        backward_ok = max_backward <= backward_tolerance
    success = reached_goal & clearance_ok & joint_limits_ok & leg_length_ok & backward_ok
    return {"success": success, "collision_free": collision_free, "reached_goal": reached_goal,
            "clearance_ok": clearance_ok, "joint_limits_ok": joint_limits_ok, "leg_length_ok": leg_length_ok,
            "backward_ok": backward_ok}


def from_samples(xp, reached_goal, clearance, limit_bad, leg_bad, heel_y, **rule) -> dict:
    """The verdict on finished paths from per-sample values along the last axis (..., N):
    ``clearance`` (m), ``limit_bad`` / ``leg_bad`` (either leg outside its joint limits / too long),
    ``heel_y`` (m); ``reached_goal`` (...) whether the path ends at the goal. Also returns
    ``min_clearance`` and ``max_backward``."""
    min_clearance = xp.min(clearance, axis=-1)
    back = heel_y[..., :-1] - heel_y[..., 1:]
    max_backward = xp.max(back, axis=-1) if back.shape[-1] else xp.zeros_like(min_clearance)
    v = verdict(xp, reached_goal, min_clearance, ~xp.any(limit_bad, axis=-1), ~xp.any(leg_bad, axis=-1),
                max_backward, **rule)
    return {**v, "min_clearance": min_clearance, "max_backward": max_backward}


def start(xp, shape=(), dtype="float32") -> dict:
    """An episode's running aggregates before its first step (``shape``: the batch of episodes)."""
    no = xp.zeros(shape, dtype=bool)
    return {"reached_goal": no, "limits": no, "leg": no,
            "min_clearance": xp.full(shape, xp.inf, dtype=dtype), "max_backward": xp.zeros(shape, dtype=dtype)}


def accumulate(xp, acc: dict, info: dict, alive=True) -> dict:
    """Fold one environment step's ``info`` (jaxexo.physics.dynamics.transition's) into ``acc``;
    steps where ``alive`` is False (after the episode ended) leave it unchanged."""
    return {
        "reached_goal": acc["reached_goal"] | (alive & info["goal_reached"]),
        "limits": acc["limits"] | (alive & info["joint_limit_violation"]),
        "leg": acc["leg"] | (alive & info["leg_length_violation"]),
        "min_clearance": xp.where(alive, xp.minimum(acc["min_clearance"], info["clearance"]), acc["min_clearance"]),
        "max_backward": xp.where(alive, xp.maximum(acc["max_backward"], info["backward"]), acc["max_backward"]),
    }


def episode_verdict(xp, acc: dict, **rule) -> dict:
    """The verdict on episodes from their running aggregates (``accumulate``)."""
    return verdict(xp, acc["reached_goal"], acc["min_clearance"], ~acc["limits"], ~acc["leg"],
                   acc["max_backward"], **rule)


def failed_checks(v: dict, i=None) -> tuple[str, ...]:
    """Names (CHECKS) of the checks a verdict failed, for swing ``i`` of a batch (NumPy values)."""
    pick = (lambda x: x) if i is None else (lambda x: x[i])
    return tuple(c for c in CHECKS if not bool(pick(v[c])))
