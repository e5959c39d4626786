"""The one scenario generator: how a scene (obstacle kind and size, position, pivot condition, start,
step length) is drawn, for the JAX environment's reset and every NumPy tool alike.

A scene is drawn from ``N_UNIFORMS`` uniform numbers by ``layout_from_uniforms`` (array-module generic,
like the rest of jaxexo.physics). The uniform numbers come from a counter-based generator,
``uniforms(xp, k0, k1, n)``: the Threefry-2x32 block cipher (Salmon et al. 2011, 20 rounds; the
cipher JAX's own PRNG uses) keyed by two 32-bit words and applied to the counters 0..n-1, in uint32
arithmetic that NumPy and JAX compute bit for bit alike. So

- ``ExoStepEnv.reset(key)`` draws its scene from the key's two words (jax.random.key_data);
- scene ``i`` of a scenario set with ``seed`` is the scene of the key words (seed, i): the same
  obstacle kind and pivot condition as the JAX environment's reset for that key, and the same sizes
  and positions (bit for bit eagerly; under jax.jit XLA may fuse ``a + b * c`` into one multiply-add
  and move a value by an ulp, about 1e-8 m);
- the sets every success figure is measured on (eval.json, validation, sweeps, ``jaxexo eval``, the
  thesis-style baseline's pool) are drawn here with NumPy and fed to JAX as arrays, so they are one
  set, bit for bit.

Test sets (``cycle=True``) fix the kind and pivot condition of scene i (kind i % kinds, pivot
(i // kinds) % 3, so every pair is equally represented) and draw the rest; the config of such a set
is ``jaxexo.config.test_config``: the five thesis obstacles (Table 3.1), all three pivot conditions.
"""

from __future__ import annotations

from jaxexo.physics import geometry, terrain
from jaxexo.physics.dynamics import pivot_position
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

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
        for r in _ROTATIONS[4 * (block % 2):4 * (block % 2) + 4]:
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
    return (bits >> 8).astype(xp.float32) * xp.float32(2.0 ** -24)


def seed_words(seed: int) -> tuple[int, int]:
    """The two key words of an integer seed (as jax.random.PRNGKey(seed) holds them)."""
    seed = int(seed)
    if not 0 <= seed < 2 ** 64:
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


def terrain_layout_from_uniforms(xp, p, u, kind=None, pivot_kind=None, families=None) -> dict:
    """A procedural-terrain scene from uniform numbers u (..., N_TERRAIN_UNIFORMS): the family (by
    ``terrain_cdf`` over ``terrain_ids``; ``kind`` fixes the index into terrain_ids), its outline
    (terrain.family_outline), the pivot condition, and the placement (terrain.place: start shift,
    step length that fits the width, centre anywhere in the gap). ``kind`` of the result is the
    family id (terrain.FAMILIES). ``families``: the config's family names (static), to evaluate
    only those outlines (the same scenes, a smaller program)."""
    D = terrain.D_MAX
    kind, pivot_kind = _kind_and_pivot(xp, u, kind, pivot_kind, p.terrain_cdf, p.terrain_pivot_cdf)
    fid = p.terrain_ids[kind]
    local, width, height = terrain.family_outline(xp, fid, u[..., 2:2 + D], families)
    start_y, step_length, center = terrain.place(
        xp, u[..., 2 + D:2 + D + 3], width, p.terrain_start_shift, p.terrain_step_length, p.foot_length,
        p.terrain_margins[..., 0], p.terrain_margins[..., 1])
    outline = xp.stack([local[..., 0] + center[..., None], local[..., 1]], axis=-1)
    return dict(outline=outline, shape=terrain.shape(xp, local, width, p.kind_shape.shape[-1]), center_y=center,
                width=width, height=height, kind=xp.asarray(fid, dtype=xp.int32), pivot_kind=pivot_kind,
                pivot_y=pivot_position(xp, pivot_kind, start_y, center), start_y=start_y,
                goal_y=start_y + step_length)


def layout_from_uniforms(xp, p, u, kind=None, pivot_kind=None, families=None) -> dict:
    """A scene from uniform numbers u (..., N_UNIFORMS) and the layout distribution in ``p``
    (jaxexo.config.param_values' fields): the Layout fields as a dict of arrays (...). ``kind``/``pivot_kind``
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
    center = geometry.default_center(p.foot_length, step_length) + lerp(u[..., 8], p.obstacle_offset)
    unit = p.kind_outlines[kind]
    outline = xp.stack([center[..., None] + width[..., None] * unit[..., 0],
                        height[..., None] * unit[..., 1]], axis=-1)
    return dict(outline=outline, shape=height[..., None] * p.kind_shape[kind], center_y=center, width=width,
                height=height, kind=kind, pivot_kind=pivot_kind,
                pivot_y=pivot_position(xp, pivot_kind, start_y, center), start_y=start_y,
                goal_y=start_y + step_length)


def scenario_layouts(xp, p, seed: int, n: int, cycle: bool = False, kinds=None, pivots=None) -> dict:
    """Scene i (i < n) of the set ``seed``: the scene reset draws from the key words (seed, i).
    ``cycle``: kinds and pivot conditions in turn instead of drawn (test sets): kind
    kinds[i % len(kinds)], pivot pivots[(i // len(kinds)) % len(pivots)], by default every kind of
    ``p`` and every pivot condition."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not 0 <= int(seed) < 2 ** 32:
        raise ValueError(f"seed must be in [0, 2**32), got {seed}")
    i = xp.arange(n, dtype=xp.uint32)
    u = uniforms(xp, xp.full((n,), int(seed), dtype=xp.uint32), i, n_uniforms(p))
    if not cycle:
        return layout_from_uniforms(xp, p, u)
    n_kinds = p.terrain_ids.shape[-1] if uses_terrain(p) else p.kind_cdf.shape[-1]
    kinds = xp.asarray(range(n_kinds) if kinds is None else kinds, dtype=xp.int32)
    pivots = xp.asarray(range(len(PIVOT_CONDITIONS)) if pivots is None else pivots, dtype=xp.int32)
    idx = xp.arange(n, dtype=xp.int32)
    return layout_from_uniforms(xp, p, u, kind=kinds[idx % len(kinds)],
                                pivot_kind=pivots[(idx // len(kinds)) % len(pivots)])


__all__ = ["TEST_KINDS", "HELD_OUT", "N_UNIFORMS", "N_TERRAIN_UNIFORMS", "threefry2x32", "uniforms", "seed_words",
           "uses_terrain", "n_uniforms", "layout_from_uniforms", "terrain_layout_from_uniforms", "scenario_layouts"]
