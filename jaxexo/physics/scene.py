"""Scenes: ``Scene``, the one record of a scene (one, or many on a leading axis: the environment's
episodes, the scenario draws, a generator's batch), ``make_scene``, the one place where a scene (an
Obstacle, a pivot condition or pivot y, a start and a step length) is validated and laid out,
``stack_scenes`` (scenes on a leading axis), and the clearance a caller may ask of a swing
(``check_clearance``, ``with_clearance``). NumPy-only.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import numpy as np

from jaxexo.physics import geometry, kinematics
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics.transition import scalar

# m: the largest clearance a caller may ask of a swing: 10 cm above the 0.28 m obstacles jaxexo
# trains on is near the default leg's joint limits; more is another task (stepping onto it).
MAX_CLEARANCE = 0.10


def check_clearance(clearance, min_clearance: float) -> float | None:
    """The clearance (m) a caller asks of a swing, validated: None (the config's env.min_clearance), or
    a number in [min_clearance, MAX_CLEARANCE]. Raises ValueError naming ``clearance``."""
    if clearance is None:
        return None
    if isinstance(clearance, bool) or not isinstance(
        clearance, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"clearance: expected a number of metres, got {type(clearance).__name__}")
    c = float(clearance)
    if not math.isfinite(c) or c < float(min_clearance) - 1e-12 or c > MAX_CLEARANCE:
        raise ValueError(
            f"clearance must be between env.min_clearance = {float(min_clearance):g} m and "
            f"{MAX_CLEARANCE:g} m, got {clearance!r}"
        )
    return c


def with_clearance(p, clearance: float | None):
    """The parameter view ``p`` (jaxexo.config's ``numpy_params`` or ``scalar_params``) for a swing that must keep
    ``clearance`` (m; None: unchanged): the verdict's margin ``min_clearance`` becomes it, and the shield
    keeps the same excess above it as the config's (``shield_clearance - min_clearance``, the budget
    the smoothed curve may cut)."""
    if clearance is None:
        return p
    extra = clearance - float(p.min_clearance)
    cast = (
        (lambda v: np.asarray(v, dtype=np.asarray(p.min_clearance).dtype))
        if isinstance(p.min_clearance, np.ndarray)
        else float
    )
    return dataclasses.replace(
        p,
        min_clearance=cast(clearance),
        shield_clearance=cast(float(p.shield_clearance) + extra),
    )


class Scene(NamedTuple):
    """Scenes in world coordinates (m, but the indices ``kind`` and ``pivot_kind``), each field with
    the same leading shape ``...``: none for one scene (``make_scene``: Python floats), ``[N]`` for
    many (``stack_scenes``, the scenario draws, the environment's episodes under vmap). A NamedTuple,
    so JAX takes it as a pytree while this floor imports NumPy only; the same observation, transition
    and checks read one scene or many.

    outline [..., K, 2]  the obstacle's world-frame outline, padded to K vertices
    shape [..., P]       its heights at P equally spaced fractions of its width
    center_y, width, height [...]
    kind [...]           the config's obstacle index, the terrain family id, or -1 (given directly)
    pivot_kind [...]     index into PIVOT_CONDITIONS, -1 for a pivot given as a y
    pivot_y, start_y, goal_y [...]  the pivot (stance) heel, the swing heel's start and its goal
    obstacle             the geometry.Obstacle of one scene (make_scene), None for many
    """

    outline: Any
    shape: Any
    center_y: Any
    width: Any
    height: Any
    kind: Any
    pivot_kind: Any
    pivot_y: Any
    start_y: Any
    goal_y: Any
    obstacle: Any = None

    @property
    def pivot(self) -> str:
        """One scene's pivot condition in words."""
        return (
            PIVOT_CONDITIONS[self.pivot_kind] if self.pivot_kind >= 0 else f"y={self.pivot_y:.3f} m"
        )


# A scene's defaults (m): the pivot heel beside the obstacle, the swing heel at the origin, the
# thesis's step (Table 3.1's layouts): make_scene's, and every generator's (jaxexo.swing.options).
DEFAULT_PIVOT = "obstacle"
DEFAULT_START_Y = 0.0
DEFAULT_STEP_LENGTH = 0.70


def make_scene(
    obstacle: geometry.Obstacle,
    pivot: str | float = DEFAULT_PIVOT,
    start_y: float = DEFAULT_START_Y,
    step_length: float = DEFAULT_STEP_LENGTH,
    *,
    foot_length: float,
    max_vertices: int | None = None,
    shape_points: int = geometry.DEFAULT_SHAPE_POINTS,
) -> Scene:
    """Validate and lay out one scene. ``pivot`` is one of PIVOT_CONDITIONS (thesis 3.1) or the pivot
    heel's y in metres. ``max_vertices`` pads the outline to a fixed K (the JAX environment's); None
    keeps the obstacle's own vertex count. Raises ValueError naming the bad argument."""
    if not isinstance(obstacle, geometry.Obstacle):
        raise TypeError(f"obstacle: expected a jaxexo Obstacle, got {type(obstacle).__name__}")
    start_y = geometry.finite("start_y", start_y)
    step_length = geometry.finite_positive("step_length", step_length)
    if isinstance(pivot, str):
        if pivot not in PIVOT_CONDITIONS:
            raise ValueError(
                f"pivot must be one of {PIVOT_CONDITIONS} or a y in metres, got {pivot!r}"
            )
        pk = PIVOT_CONDITIONS.index(pivot)
        py = kinematics.pivot_position(scalar, pk, start_y, obstacle.center_y)
    else:
        pk, py = -1, geometry.finite("pivot_y", pivot)
    if obstacle.left <= start_y + foot_length:
        raise ValueError(
            f"obstacle: its near edge ({obstacle.left:.4g} m) must lie ahead of the toe at "
            f"the start ({start_y + foot_length:.4g} m: start_y {geometry.as_given(start_y)} m "
            f"and the foot's {foot_length:g} m)"
        )
    if obstacle.right >= start_y + step_length:
        raise ValueError(
            f"step_length: the goal ({start_y + step_length:.4g} m) must lie beyond the "
            f"obstacle's far edge ({obstacle.right:.4g} m)"
        )
    n_vertices = len(obstacle.unit_vertices)
    max_vertices = n_vertices if max_vertices is None else max_vertices
    if n_vertices > max_vertices:
        raise ValueError(
            f"obstacle: its outline has {n_vertices} vertices, more than this model's "
            f"{max_vertices} (env.max_vertices)"
        )
    shape = obstacle.height * geometry.cached_shape_descriptor(obstacle.unit_vertices, shape_points)
    return Scene(
        outline=obstacle.outline_array(max_vertices),
        shape=shape,
        center_y=obstacle.center_y,
        width=obstacle.width,
        height=obstacle.height,
        kind=-1,
        pivot_kind=pk,
        pivot_y=float(py),
        start_y=start_y,
        goal_y=start_y + step_length,
        obstacle=obstacle,
    )


def stack_scenes(scenes, dtype=np.float32) -> Scene:
    """Single scenes as one ``Scene`` [N] (outlines padded to the largest vertex count; the indices
    int32, the rest ``dtype``; no obstacles)."""
    k = max(len(s.outline) for s in scenes)
    f = lambda name: np.asarray([getattr(s, name) for s in scenes], dtype=dtype)  # noqa: E731
    i32 = lambda name: np.asarray([getattr(s, name) for s in scenes], dtype=np.int32)  # noqa: E731
    return Scene(
        outline=np.stack([geometry.pad_outline(s.outline, k) for s in scenes]).astype(dtype),
        shape=np.stack([s.shape for s in scenes]).astype(dtype),
        center_y=f("center_y"),
        width=f("width"),
        height=f("height"),
        kind=i32("kind"),
        pivot_kind=i32("pivot_kind"),
        pivot_y=f("pivot_y"),
        start_y=f("start_y"),
        goal_y=f("goal_y"),
    )
