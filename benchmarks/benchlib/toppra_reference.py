"""The velocity-acceleration time optimum of a timed swing's own joint path, by toppra (an
independent TOPP-RA implementation; the bench/test extras install it): the reference a timed swing's
duration is quoted against (docs/device-timing.md). Not imported by the package."""

from __future__ import annotations

import logging

import numpy as np

GRID = 2001  # toppra's grid on the path parameter (its constraints hold at these points)


def va_optimum(swing, limits=None, grid: int = GRID) -> float:
    """The shortest rest-to-rest duration (s) of ``swing``'s joint path (``swing.curve.path``, the
    not-a-knot cubic spline through its knots) under the joint velocity and acceleration limits
    ``limits`` (default: ``swing.limits.planned()``, what the swing was timed against), no jerk
    limit: toppra's TOPP-RA on ``grid`` points. Its constraints hold at the grid points only, so it
    is at most the true optimum (a swing within the limits is never shorter)."""
    import toppra
    import toppra.algorithm
    import toppra.constraint

    logging.getLogger("toppra").setLevel(logging.ERROR)  # its per-call INFO lines
    limits = swing.limits.planned() if limits is None else limits
    path = swing.curve.path
    q = path.derivatives(path.knots, 0)[0]
    spline = toppra.SplineInterpolator(path.knots, q, bc_type="not-a-knot")
    v, a = np.asarray(limits.velocity), np.asarray(limits.acceleration)
    constraints = [
        toppra.constraint.JointVelocityConstraint(np.stack([-v, v], axis=1)),
        toppra.constraint.JointAccelerationConstraint(np.stack([-a, a], axis=1)),
    ]
    algo = toppra.algorithm.TOPPRA(
        constraints,
        spline,
        gridpoints=np.linspace(0.0, 1.0, grid),
        parametrizer="ParametrizeConstAccel",
    )
    traj = algo.compute_trajectory(0.0, 0.0)
    if traj is None:
        raise ValueError("toppra found no feasible parametrisation of this path")
    return float(traj.duration)
