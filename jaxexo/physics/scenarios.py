"""The one scenario generator: how a scene (obstacle, position, pivot condition, start, step length)
is drawn, for the JAX environment's reset and every NumPy tool alike.

``layout_from_uniforms`` turns ``N_UNIFORMS`` numbers of ``uniforms`` (Threefry-2x32, bit for bit
alike in NumPy and JAX) into a layout; ``generate`` draws the scene sets the tools use (the
training and test layouts, the safe-swing checks' shifted layouts, the held-out families, the
timing shapes). Why and how: docs/training.md#the-environment.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from jaxexo.physics import geometry, terrain
from jaxexo.physics.geometry import Obstacle
from jaxexo.physics.kinematics import PIVOT_CONDITIONS, pivot_position
from jaxexo.physics.scene import Scene

# The five thesis obstacles (Table 3.1; Base 1-3 seen in training, triangle and half-circle held out).
TEST_KINDS = ("base1", "base2", "base3", "triangle", "half_circle")
HELD_OUT = ("triangle", "half_circle")
# Uniform numbers per scene: kind, pivot, width and height jitter, width, height, step length,
# start shift, obstacle offset.
N_UNIFORMS = 9
# With [layout] terrain: family, pivot, D_MAX shape numbers (terrain.family_outline), then start
# shift, step length and centre (terrain.place).
N_TERRAIN_UNIFORMS = 2 + terrain.D_MAX + 3

_ROTATIONS = (13, 15, 26, 6, 17, 29, 16, 24)
_PARITY = 0x1BD11BDA


def _rotl(x, r):
    return (x << r) | (x >> (32 - r))


def threefry2x32(xp, k0, k1, x0, x1):
    """Threefry-2x32, 20 rounds: encrypts the counter pair (x0, x1) under the key (k0, k1); all uint32
    arrays broadcast together. Returns the two output words."""
    u32 = lambda v: xp.asarray(v, dtype=xp.uint32)  # noqa: E731
    ks = (u32(k0), u32(k1), u32(k0) ^ u32(k1) ^ u32(_PARITY))
    x0, x1 = u32(x0) + ks[0], u32(x1) + ks[1]
    for block in range(5):
        for r in _ROTATIONS[4 * (block % 2) : 4 * (block % 2) + 4]:
            x0 = x0 + x1
            x1 = _rotl(x1, r) ^ x0
        x0 = x0 + ks[(block + 1) % 3]
        x1 = x1 + ks[(block + 2) % 3] + u32(block + 1)
    return x0, x1


def uniforms(xp, k0, k1, n: int = N_UNIFORMS):
    """n uniform float32 numbers in [0, 1) per key (k0, k1) (any broadcast shape S): (*S, n).

    The top 24 bits of each cipher word, times 2^-24: exact in float32, so NumPy and JAX agree."""
    k0 = xp.asarray(k0, dtype=xp.uint32)[..., None]
    k1 = xp.asarray(k1, dtype=xp.uint32)[..., None]
    count = xp.arange(n, dtype=xp.uint32)
    bits, _ = threefry2x32(xp, k0, k1, count, xp.zeros_like(count))
    return (bits >> 8).astype(xp.float32) * xp.float32(2.0**-24)


def seed_words(seed: int) -> tuple[int, int]:
    """The two key words of an integer seed (as jax.random.PRNGKey(seed) holds them)."""
    seed = int(seed)
    if not 0 <= seed < 2**64:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    return seed >> 32, seed & 0xFFFFFFFF


def _categorical(xp, u, cdf):
    """Inverse-CDF draw of an index from uniform u (...) and a CDF (..., m)."""
    return xp.minimum(xp.sum((u[..., None] >= cdf).astype(xp.int32), axis=-1), cdf.shape[-1] - 1)


def uses_terrain(p) -> bool:
    """Whether the params describe procedural terrain ([layout] terrain): a static switch, read from
    the shape of ``terrain_ids`` (length 0 when off), so that it holds under jit and vmap."""
    return p.terrain_ids.shape[-1] > 0


def n_uniforms(p) -> int:
    """Uniform numbers per scene for these params."""
    return N_TERRAIN_UNIFORMS if uses_terrain(p) else N_UNIFORMS


def _kind_and_pivot(xp, u, kind, pivot_kind, kind_cdf, pivot_cdf):
    """The obstacle kind and pivot condition of a scene (int32): drawn from u[0] / u[1] by their CDFs
    unless given."""
    if kind is None:
        kind = _categorical(xp, u[..., 0], kind_cdf)
    if pivot_kind is None:
        pivot_kind = _categorical(xp, u[..., 1], pivot_cdf)
    return xp.asarray(kind, dtype=xp.int32), xp.asarray(pivot_kind, dtype=xp.int32)


def terrain_layout_from_uniforms(xp, p, u, kind=None, pivot_kind=None, families=None) -> Scene:
    """A procedural-terrain scene from uniform numbers u (..., N_TERRAIN_UNIFORMS): the family (by
    ``terrain_cdf`` over ``terrain_ids``; ``kind`` fixes the index into terrain_ids), its outline
    (terrain.family_outline), the pivot condition, and the placement (terrain.place: start shift,
    step length that fits the width, centre anywhere in the gap). ``kind`` of the result is the
    family id (terrain.FAMILIES). ``families``: the config's family names (static), to evaluate
    only those outlines (the same scenes, a smaller program)."""
    D = terrain.D_MAX
    kind, pivot_kind = _kind_and_pivot(xp, u, kind, pivot_kind, p.terrain_cdf, p.terrain_pivot_cdf)
    fid = p.terrain_ids[kind]
    local, width, height = terrain.family_outline(xp, fid, u[..., 2 : 2 + D], families)
    start_y, step_length, center = terrain.place(
        xp,
        u[..., 2 + D : 2 + D + 3],
        width,
        p.terrain_start_shift,
        p.terrain_step_length,
        p.foot_length,
        p.terrain_margins[..., 0],
        p.terrain_margins[..., 1],
    )
    outline = xp.stack([local[..., 0] + center[..., None], local[..., 1]], axis=-1)
    return Scene(
        outline=outline,
        shape=terrain.shape(xp, local, width, p.kind_shape.shape[-1]),
        center_y=center,
        width=width,
        height=height,
        kind=xp.asarray(fid, dtype=xp.int32),
        pivot_kind=pivot_kind,
        pivot_y=pivot_position(xp, pivot_kind, start_y, center),
        start_y=start_y,
        goal_y=start_y + step_length,
    )


def layout_from_uniforms(xp, p, u, kind=None, pivot_kind=None, families=None) -> Scene:
    """A scene from uniform numbers u (..., N_UNIFORMS) and the layout distribution in ``p``
    (jaxexo.config.param_values' fields): the scenes as a ``Scene`` [...]. ``kind``/``pivot_kind``
    (...) fix the obstacle kind / pivot condition instead of drawing them from u[0] / u[1]. With
    procedural terrain (``uses_terrain(p)``) the scene is terrain_layout_from_uniforms'."""
    if uses_terrain(p):
        return terrain_layout_from_uniforms(xp, p, u, kind, pivot_kind, families)
    kind, pivot_kind = _kind_and_pivot(xp, u, kind, pivot_kind, p.kind_cdf, p.pivot_cdf)
    lerp = lambda x, r: r[..., 0] + (r[..., 1] - r[..., 0]) * x  # noqa: E731
    width = lerp(u[..., 4], p.kind_width[kind]) * (1.0 + (2.0 * u[..., 2] - 1.0) * p.size_jitter)
    height = lerp(u[..., 5], p.kind_height[kind]) * (1.0 + (2.0 * u[..., 3] - 1.0) * p.size_jitter)
    step_length = lerp(u[..., 6], p.step_length)
    start_y = lerp(u[..., 7], p.start_shift)
    center = geometry.default_center(p.foot_length, step_length) + lerp(
        u[..., 8], p.obstacle_offset
    )
    unit = p.kind_outlines[kind]
    outline = xp.stack(
        [center[..., None] + width[..., None] * unit[..., 0], height[..., None] * unit[..., 1]],
        axis=-1,
    )
    return Scene(
        outline=outline,
        shape=height[..., None] * p.kind_shape[kind],
        center_y=center,
        width=width,
        height=height,
        kind=kind,
        pivot_kind=pivot_kind,
        pivot_y=pivot_position(xp, pivot_kind, start_y, center),
        start_y=start_y,
        goal_y=start_y + step_length,
    )


def scenario_layouts(
    xp, p, seed: int, n: int, cycle: bool = False, kinds=None, pivots=None
) -> Scene:
    """Scene i (i < n) of the set ``seed``: the scene reset draws from the key words (seed, i).
    ``cycle``: kinds and pivot conditions in turn instead of drawn (test sets): kind
    kinds[i % len(kinds)], pivot pivots[(i // len(kinds)) % len(pivots)], by default every kind of
    ``p`` and every pivot condition."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not 0 <= int(seed) < 2**32:
        raise ValueError(f"seed must be in [0, 2**32), got {seed}")
    i = xp.arange(n, dtype=xp.uint32)
    u = uniforms(xp, xp.full((n,), int(seed), dtype=xp.uint32), i, n_uniforms(p))
    if not cycle:
        return layout_from_uniforms(xp, p, u)
    n_kinds = p.terrain_ids.shape[-1] if uses_terrain(p) else p.kind_cdf.shape[-1]
    kinds = xp.asarray(range(n_kinds) if kinds is None else kinds, dtype=xp.int32)
    pivots = xp.asarray(range(len(PIVOT_CONDITIONS)) if pivots is None else pivots, dtype=xp.int32)
    idx = xp.arange(n, dtype=xp.int32)
    return layout_from_uniforms(
        xp, p, u, kind=kinds[idx % len(kinds)], pivot_kind=pivots[(idx // len(kinds)) % len(pivots)]
    )


# --------------------------------------------------------------------------------------------
# Scene sets as ``Scenario`` records, ``generate``'s arguments (NumPy only: tools, tests, benchmarks)
# --------------------------------------------------------------------------------------------


class Scenario(NamedTuple):
    """One scene of a NumPy scene set, as ``generate`` takes it: ``kind`` (the obstacle kind, or the
    terrain family's name), ``obstacle`` (a geometry.Obstacle in the world frame, m), ``pivot`` (one
    of PIVOT_CONDITIONS), ``start_y`` (m, the swing heel's start) and ``step_length`` (m);
    ``family_u`` [D_MAX] the terrain family's shape numbers (terrain.family_outline), held-out sets
    only, else None."""

    kind: str
    obstacle: Obstacle
    pivot: str
    start_y: float
    step_length: float
    family_u: list[float] | None = None

    def options(self) -> dict:
        """``generate``'s keyword arguments after the obstacle: pivot, start_y, step_length."""
        return {"pivot": self.pivot, "start_y": self.start_y, "step_length": self.step_length}


def batch_options(scenes) -> dict[str, list]:
    """``generate_batch``'s per-scene keyword arguments (pivot, start_y, step_length) of Scenarios."""
    return {k: [getattr(s, k) for s in scenes] for k in ("pivot", "start_y", "step_length")}


def as_scenarios(lay: Scene, obstacles=None) -> list[Scenario]:
    """Scenes ``lay`` [N] (``scenario_layouts``') as Scenarios: ``obstacles`` are the layout's
    obstacle mixture (objects with ``kind``, ``shape`` and ``unit_vertices()``, indexed by the
    layouts' ``kind``), None for procedural terrain (``kind`` is the family id and the outline is in
    the world frame)."""
    out = []
    for i in range(len(lay.start_y)):
        w, h, center = (float(getattr(lay, k)[i]) for k in ("width", "height", "center_y"))
        if obstacles is None:  # kind is the family id; the outline is world-frame
            local = np.asarray(lay.outline[i], dtype=np.float64) - np.array([center, 0.0])
            kind, ob = terrain.FAMILY_NAMES[int(lay.kind[i])], terrain.to_obstacle(local, center)
        elif (spec := obstacles[int(lay.kind[i])]).shape == "profile":
            kind, ob = spec.kind, Obstacle("profile", "profile", center, w, h, spec.unit_vertices())
        else:
            kind, ob = spec.kind, getattr(Obstacle, spec.shape)(w, h, center_y=center)
        pivot, start = PIVOT_CONDITIONS[int(lay.pivot_kind[i])], float(lay.start_y[i])
        out.append(Scenario(kind, ob, pivot, start, float(lay.goal_y[i]) - start))
    return out


UNSEEN_SHAPES = ("rectangle", "wedge", "pole", "bumps")


def _unseen_obstacle(rng, shape: str, center: float) -> Obstacle:
    """An obstacle of a family the default policy never trained on (the safe-swing checks)."""
    if shape == "rectangle":
        return Obstacle.rectangle(rng.uniform(0.04, 0.25), rng.uniform(0.04, 0.20), center_y=center)
    if shape == "pole":
        return Obstacle.rectangle(rng.uniform(0.01, 0.04), rng.uniform(0.05, 0.20), center_y=center)
    w, h = rng.uniform(0.08, 0.25), rng.uniform(0.05, 0.20)
    if shape == "wedge":  # a ramp rising (or falling) to a vertical face
        z = [0.0, h] if rng.uniform() < 0.5 else [h, 0.0]
        return Obstacle.profile([[center - w / 2, z[0]], [center + w / 2, z[1]]])
    k = int(rng.integers(2, 4))  # "bumps": k humps of random heights with dips between them
    y = np.linspace(center - w / 2, center + w / 2, 2 * k + 1)
    z = np.zeros(2 * k + 1)
    z[1::2] = h * rng.uniform(0.5, 1.0, k)
    z[2:-1:2] = h * rng.uniform(0.0, 0.4, k - 1)
    return Obstacle.profile(np.column_stack([y, z]))


def safety_scenes(
    foot_length: float, step_length, n: int, seed: int = 2024, unseen: bool = False
) -> list[Scenario]:
    """n shifted layouts for the safe-swing checks (``foot_length`` m, ``step_length`` a range [lo, hi] m): the start anywhere in 0-10 cm, the obstacle anywhere
    in the gap between the toe at the start and the goal (terrain.NEAR_MARGIN = 2.5 cm from the toe,
    terrain.FAR_MARGIN = 6 cm from the goal: procedural terrain's placement margins), every pivot condition in
    turn; the five thesis obstacles (kind i % 5) or, with ``unseen``, shapes never trained on
    (UNSEEN_SHAPES in turn: random rectangles, wedges, thin poles, profiles with several bumps)."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    rng = np.random.default_rng(seed)
    foot, (l_lo, l_hi) = foot_length, step_length
    kinds = UNSEEN_SHAPES if unseen else TEST_KINDS
    out = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        start, step = rng.uniform(0.0, 0.10), rng.uniform(l_lo, l_hi)
        probe = _unseen_obstacle(rng, kind, 0.0) if unseen else Obstacle.named(kind, center_y=0.0)
        # the gap as procedural terrain places obstacles (terrain.place's margins): the foot at the
        # start clears the default 2 cm margin with 5 mm to spare, so every scene admits a safe swing
        lo = start + foot + terrain.NEAR_MARGIN + probe.width / 2
        hi = start + step - terrain.FAR_MARGIN - probe.width / 2
        center = rng.uniform(lo, max(lo, hi))
        ob = (
            Obstacle.profile(probe.outline + [center, 0.0])
            if probe.shape == "profile"
            else (getattr(Obstacle, probe.shape)(probe.width, probe.height, center_y=center))
        )
        if not unseen:
            ob = Obstacle.named(kind, center_y=center)
        pivot = PIVOT_CONDITIONS[(i // len(kinds)) % 3]
        out.append(Scenario(kind, ob, pivot, float(start), float(step)))
    return out


# --------------------------------------------------------------------------------------------
# The held-out benchmark's scenes: families no training draws (terrain.HELD_OUT_FAMILIES)
# --------------------------------------------------------------------------------------------

UNSEEN_SEED = 20_261_122
UNSEEN_START_SHIFT = (0.0, 0.12)  # m, the agent starts up to 12 cm closer to the obstacle
UNSEEN_STEP_LENGTH = (0.55, 0.85)  # m
UNSEEN_LEVELS = (0.0, 0.5, 1.0)  # fractions of the start and step-length ranges
CELLS_PER_FAMILY = len(PIVOT_CONDITIONS) * len(UNSEEN_LEVELS) * len(UNSEEN_LEVELS)


def repeats_for(n: int, families=terrain.HELD_OUT_FAMILIES) -> int:
    """Draws per (family, pivot, start, step length) cell so that the set has at least n scenes."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    return max(1, math.ceil(n / (len(families) * CELLS_PER_FAMILY)))


def unseen_scenarios(
    foot_length: float,
    repeats: int = 2,
    seed: int = UNSEEN_SEED,
    families=terrain.HELD_OUT_FAMILIES,
) -> list[Scenario]:
    """The held-out scene set: families x pivots x starts x step lengths x ``repeats`` draws (shape
    and position). The families are terrain.HELD_OUT_FAMILIES (excluded from training by
    construction), the starts 0, 6 and 12 cm closer to the obstacle, the step lengths the shortest
    that fits the drawn obstacle, the middle and the longest of 0.55-0.85 m; shapes and positions in
    the gap come from NumPy Generators seeded with the fixed ``UNSEEN_SEED``, so numbers are
    comparable between models (do not tune a model to it). Scenarios with ``kind`` the family name
    and ``family_u`` the shape's uniform numbers (to reproduce it with terrain.family_outline)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    for f in families:
        terrain.family_id(f)  # names the bad family
    out = []
    for fi, fam in enumerate(families):
        # One Generator per family: adding a family never changes another family's scenes.
        rng = np.random.default_rng([seed, fi])
        n = CELLS_PER_FAMILY * repeats
        u_shape, u_place = terrain.draw_uniforms(rng, n)
        outline, width, _ = terrain.one_family_outline(np, fam, u_shape.astype(np.float64))
        i = 0
        for pk, pivot in enumerate(PIVOT_CONDITIONS):
            for a in UNSEEN_LEVELS:
                for b in UNSEEN_LEVELS:
                    for _ in range(repeats):
                        u = np.array([a, b, u_place[i, 2]], dtype=np.float64)
                        start, L, c = terrain.place(
                            np, u, width[i], UNSEEN_START_SHIFT, UNSEEN_STEP_LENGTH, foot_length
                        )
                        ob = terrain.to_obstacle(outline[i], float(c))
                        u = u_shape[i].tolist()
                        out.append(Scenario(fam, ob, pivot, float(start), float(L), u))
                        i += 1
    return out


def shape_scenarios(n: int, seed: int = 2024) -> list[Scenario]:
    """n scenes for device timing, shapes and sizes outside the thesis set: triangles, half-ellipses and four-point profiles of
    random size (width 8-22 cm, height 5-25 cm), the three pivot conditions in turn."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        w, h, c = rng.uniform(0.08, 0.22), rng.uniform(0.05, 0.25), 0.45 + rng.uniform(-0.03, 0.03)
        k = i % 3
        if k == 0:
            ob, kind = Obstacle.triangle(w, h, center_y=c), "triangle"
        elif k == 1:
            ob, kind = Obstacle.half_ellipse(w, h, center_y=c), "half_ellipse"
        else:
            a, b = sorted(rng.uniform(-0.4, 0.4, 2) * w)
            ob = Obstacle.profile(
                [(c - w / 2, 0.0), (c + a, h), (c + b, rng.uniform(0.5, 1.0) * h), (c + w / 2, 0.0)]
            )
            kind = "profile"
        out.append(Scenario(kind, ob, PIVOT_CONDITIONS[(i // 3) % 3], 0.0, 0.70))
    return out


__all__ = [
    "TEST_KINDS",
    "HELD_OUT",
    "N_UNIFORMS",
    "N_TERRAIN_UNIFORMS",
    "threefry2x32",
    "uniforms",
    "seed_words",
    "uses_terrain",
    "n_uniforms",
    "layout_from_uniforms",
    "terrain_layout_from_uniforms",
    "scenario_layouts",
    "Scenario",
    "batch_options",
    "as_scenarios",
    "safety_scenes",
    "UNSEEN_SHAPES",
    "UNSEEN_SEED",
    "CELLS_PER_FAMILY",
    "repeats_for",
    "unseen_scenarios",
    "shape_scenarios",
]
