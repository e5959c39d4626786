"""The [layout] section's obstacle mixture and procedural terrain (``TerrainSpec``): parsing, writing
back, and the EnvParams leaves they become (the kinds' outlines, shapes, sizes and cumulative
weights; the terrain families of jaxexo.physics.terrain). The obstacles of thesis Table 3.1 are named by their kind alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from jaxexo.config.checks import ConfigError, _number, _range, _vector, pivot_weights
from jaxexo.physics import geometry
from jaxexo.physics.geometry import THESIS_OBSTACLES
from jaxexo.physics.terrain import (
    FAMILIES,
    FAMILY_NAMES,
    FAR_MARGIN,
    NEAR_MARGIN,
    TRAIN_FAMILIES,
    TerrainError,
    min_step_length,
    unclearable,
)


def cdf(weights) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    c = np.cumsum(w / w.sum())
    c[-1] = 1.0
    return c.astype(np.float32)


@dataclass(frozen=True)
class ObstacleSpec:
    """One entry of the layout's obstacle mixture.

    ``kind`` is a thesis obstacle (base1, base2, base3, triangle, half_circle: the fixed size of thesis
    Table 3.1) or a shape (rectangle, triangle, half_ellipse, profile) with ``width`` and ``height``
    ranges [lo, hi] in m. The name "triangle" is both: without a size it is the thesis triangle, with
    ``width`` and ``height`` the shape (the thesis triangle is the shape at 0.20 x 0.20 m, so both
    readings of an equal spec agree). A ``profile`` takes ``points`` (y, z), y relative to the
    obstacle centre, and is scaled to ``width`` and ``height`` ranges in metres (default: its own
    extents, as drawn)."""

    kind: str
    width: tuple[float, float]
    height: tuple[float, float]
    weight: float = 1.0
    shape: str = "rectangle"
    points: tuple[tuple[float, float], ...] = ()

    def unit_vertices(self) -> np.ndarray:
        if self.shape == "profile":
            return geometry.Obstacle.profile(self.points).unit_vertices
        return geometry.unit_profile(self.shape)

    @property
    def is_thesis(self) -> bool:
        """Exactly a thesis obstacle of Table 3.1 (written as its name alone)."""
        return self.kind in THESIS_OBSTACLES and self == named_spec(self.kind, self.weight)

    def to_toml(self) -> dict:
        """The TOML table that ``parse_obstacle`` reads back to this spec."""
        if self.is_thesis:
            return {"kind": self.kind, "weight": self.weight}
        d = {
            "kind": self.kind,
            "weight": self.weight,
            "width": list(self.width),
            "height": list(self.height),
        }
        if self.kind == "profile":
            d["points"] = [list(p) for p in self.points]
        return d


def named_spec(kind: str, weight: float = 1.0) -> ObstacleSpec:
    shape, w, h = THESIS_OBSTACLES[kind]
    return ObstacleSpec(kind, (w, w), (h, h), weight, shape)


# Width and height ranges: the one obstacle-size bound (jaxexo.physics.geometry), as for the generators.
SIZE = {
    "width": dict(positive=True, hi=geometry.MAX_OBSTACLE_WIDTH),
    "height": dict(positive=True, hi=geometry.MAX_OBSTACLE_HEIGHT),
}
# Placement ranges of the terrain (m): a start shift within a metre, a step of at most 2 m.
MAX_SHIFT = 1.0
MAX_STEP_LENGTH = 2.0


def parse_obstacle(path: str, raw: Any) -> ObstacleSpec:
    if isinstance(raw, str):
        raw = {"kind": raw}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a table or a thesis obstacle name, got {raw!r}")
    known = {"kind", "width", "height", "weight", "points"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(sorted(known))})")
    kind = raw.get("kind")
    weight = _number(f"{path}.weight", raw.get("weight", 1.0), nonneg=True)
    sized = any(k in raw for k in ("width", "height", "points"))
    if kind in THESIS_OBSTACLES and not sized:
        return named_spec(kind, weight)
    shapes = geometry.SHAPES
    if kind in THESIS_OBSTACLES and kind not in shapes:
        k = next(k for k in ("width", "height", "points") if k in raw)
        raise ConfigError(
            f"{path}.{k}: {kind} has the fixed size of thesis Table 3.1; "
            f'use kind = "{THESIS_OBSTACLES[kind][0]}" for other sizes'
        )
    if kind not in shapes:
        raise ConfigError(
            f"{path}.kind: must be a thesis obstacle {sorted(THESIS_OBSTACLES)} "
            f"or a shape {list(shapes)}, got {kind!r}"
        )
    if kind != "profile":
        if "points" in raw:
            raise ConfigError(f'{path}.points: only kind = "profile" takes points')
        for k in ("width", "height"):
            if k not in raw:
                raise ConfigError(
                    f'{path}.{k}: required for kind = "{kind}" (a range [lo, hi] in m)'
                )
        width = _range(f"{path}.width", raw["width"], **SIZE["width"])
        height = _range(f"{path}.height", raw["height"], **SIZE["height"])
        return ObstacleSpec(kind, width, height, weight, kind)
    if "points" not in raw:
        raise ConfigError(f'{path}.points: required for kind = "profile"')
    pts = raw["points"]
    if not isinstance(pts, (list, tuple)) or not all(isinstance(p, (list, tuple)) for p in pts):
        raise ConfigError(f"{path}.points: expected a list of [y, z] pairs in m, got {pts!r}")
    points = tuple(_vector(f"{path}.points[{i}]", p, 2) for i, p in enumerate(pts))
    try:
        ob = geometry.Obstacle.profile(points)
    except geometry.GeometryError as e:
        raise ConfigError(f"{path}.points: {e}") from None
    width = _range(f"{path}.width", raw.get("width", [ob.width, ob.width]), **SIZE["width"])
    height = _range(f"{path}.height", raw.get("height", [ob.height, ob.height]), **SIZE["height"])
    return ObstacleSpec(kind, width, height, weight, kind, points)


def parse_obstacles(path: str, v: Any) -> tuple[ObstacleSpec, ...]:
    if not isinstance(v, (list, tuple)) or not v:
        raise ConfigError(f"{path}: expected a non-empty list of obstacles")
    return tuple(
        o if isinstance(o, ObstacleSpec) else parse_obstacle(f"{path}[{i}]", o)
        for i, o in enumerate(v)
    )


class ObstacleLeaves(NamedTuple):
    """The obstacle mixture's EnvParams leaves (B kinds, K outline vertices, P shape points)."""

    kind_outlines: np.ndarray  # [B, K, 2] padded unit outlines
    kind_shape: np.ndarray  # [B, P] shape descriptors
    kind_cdf: np.ndarray  # [B] the kinds' cumulative probabilities
    kind_width: np.ndarray  # [B, 2] m, width range
    kind_height: np.ndarray  # [B, 2] m, height range


def obstacle_params(obstacles: tuple[ObstacleSpec, ...], cfg) -> ObstacleLeaves:
    """The layout's obstacle mixture as EnvParams leaves: padded unit outlines (B, K, 2), shape
    descriptors (B, P), the kinds' cumulative probabilities and their size ranges (m)."""
    outlines = np.stack(
        [geometry.pad_outline(o.unit_vertices(), cfg.outline_vertices) for o in obstacles]
    )
    shapes = np.stack([geometry.shape_descriptor(u, cfg.env.shape_points) for u in outlines])
    f = lambda x: np.asarray(x, dtype=np.float32)  # noqa: E731
    return ObstacleLeaves(
        kind_outlines=f(outlines),
        kind_shape=f(shapes),
        kind_cdf=cdf([o.weight for o in obstacles]),
        kind_width=f([o.width for o in obstacles]),
        kind_height=f([o.height for o in obstacles]),
    )


def default_obstacles() -> tuple[ObstacleSpec, ...]:
    """Obstacle mixture of the default model (configs/default.toml): Base 1-3 and random rectangles
    up to 22 cm wide and 28 cm high (triangle and half-circle are held out for testing). With the
    default terrain it sets the thesis-five test set only; reset draws the terrain families."""
    return tuple(named_spec(k) for k in ("base1", "base2", "base3")) + (
        ObstacleSpec("rectangle", (0.05, 0.22), (0.05, 0.28), 1.0, "rectangle"),
        ObstacleSpec("rectangle", (0.15, 0.22), (0.18, 0.28), 1.0, "rectangle"),
    )


def _terrain_range(path, v, lo_bound=0.0):
    try:
        a, b = (float(x) for x in v)
    except (TypeError, ValueError):
        raise TerrainError(f"{path}: expected [lo, hi] in metres, got {v!r}") from None
    if not (math.isfinite(a) and math.isfinite(b)):
        raise TerrainError(f"{path}: must be finite, got {v!r}")
    if a < lo_bound or b < a:
        raise TerrainError(f"{path}: need {lo_bound} <= lo <= hi, got [{a}, {b}]")
    return (a, b)


@dataclass(frozen=True)
class TerrainSpec:
    """Procedural obstacles for training: which families (by name; held-out ones are refused unless
    ``allow_held_out``), their weights, the start shift and step length ranges (m), the pivot
    condition weights (PIVOT_CONDITIONS order) and the placement margins (m). Validated on
    construction; ``path`` prefixes error messages (the config field it came from). The families
    and their placement are jaxexo.physics.terrain's."""

    families: tuple[str, ...] = TRAIN_FAMILIES
    weights: tuple[float, ...] = ()
    start_shift: tuple[float, float] = (0.0, 0.12)
    step_length: tuple[float, float] = (0.55, 0.85)
    pivot: tuple[float, float, float] = (1.0, 1.0, 1.0)
    near_margin: float = NEAR_MARGIN
    far_margin: float = FAR_MARGIN
    allow_held_out: bool = False
    path: str = "layout.terrain"

    def __post_init__(self):
        p = self.path
        fams = tuple(self.families)
        if not fams:
            raise TerrainError(f"{p}.families: name at least one of {TRAIN_FAMILIES}")
        for f in fams:
            if f not in FAMILIES:
                raise TerrainError(
                    f"{p}.families: unknown family {f!r} (known: {', '.join(FAMILY_NAMES)})"
                )
            if FAMILIES[f].held_out and not self.allow_held_out:
                raise TerrainError(
                    f"{p}.families: {f!r} is held out for the unseen benchmark "
                    f"(training families: {', '.join(TRAIN_FAMILIES)})"
                )
        if len(set(fams)) != len(fams):
            raise TerrainError(f"{p}.families: a family is listed twice")
        weights = tuple(self.weights) if self.weights else (1.0,) * len(fams)
        if len(weights) != len(fams):
            raise TerrainError(f"{p}.weights: {len(weights)} weights for {len(fams)} families")
        if (
            any(not (isinstance(w, (int, float)) and math.isfinite(w) and w >= 0) for w in weights)
            or sum(weights) <= 0
        ):
            raise TerrainError(
                f"{p}.weights: need finite weights >= 0 with a positive sum, got {list(weights)}"
            )
        piv = tuple(float(x) for x in self.pivot)
        if len(piv) != 3 or any(not math.isfinite(x) or x < 0 for x in piv) or sum(piv) <= 0:
            raise TerrainError(
                f"{p}.pivot: three weights >= 0 (agent, obstacle, between) with a positive sum, "
                f"got {list(self.pivot)}"
            )
        for name in ("near_margin", "far_margin"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise TerrainError(f"{p}.{name}: must be > 0 metres, got {v!r}")
        object.__setattr__(self, "families", fams)
        object.__setattr__(self, "weights", tuple(float(w) for w in weights))
        object.__setattr__(self, "pivot", piv)
        object.__setattr__(
            self, "start_shift", _terrain_range(f"{p}.start_shift", self.start_shift)
        )
        object.__setattr__(
            self, "step_length", _terrain_range(f"{p}.step_length", self.step_length, 1e-9)
        )

    @property
    def ids(self) -> np.ndarray:
        return np.asarray([FAMILIES[f].fid for f in self.families], dtype=np.int32)

    @property
    def cdf(self) -> np.ndarray:
        c = np.cumsum(np.asarray(self.weights) / sum(self.weights))
        c[-1] = 1.0
        return c

    @property
    def max_width(self) -> float:
        return max(FAMILIES[f].width[1] for f in self.families)

    @property
    def max_height(self) -> float:
        return max(FAMILIES[f].height[1] for f in self.families)

    @property
    def min_size(self) -> float:
        """The smallest width or height any family draws (compare with the env's step size)."""
        return min(min(FAMILIES[f].width[0], FAMILIES[f].height[0]) for f in self.families)

    def check(
        self,
        *,
        foot_length: float,
        thigh: float,
        shin: float,
        hip_limits,
        knee_limits,
        heel_lift: float,
        goal_tolerance: float,
    ) -> None:
        """Refuse a spec the scene cannot hold or the leg cannot clear (raises TerrainError naming
        the field). ``heel_lift``: env.mid_goal_clearance - env.mid_goal_half_size[1];
        ``goal_tolerance``: env.goal_tolerance[0]."""
        p = self.path
        if self.far_margin <= goal_tolerance:
            raise TerrainError(
                f"{p}.far_margin: {self.far_margin} m must exceed the goal tolerance "
                f"{goal_tolerance} m, or the goal box reaches the obstacle"
            )
        need = min_step_length(self.max_width, foot_length, self.near_margin, self.far_margin)
        if self.step_length[1] < need:
            raise TerrainError(
                f"{p}.step_length: the longest step {self.step_length[1]} m cannot hold the "
                f"widest obstacle ({self.max_width} m): it needs {need:.3f} m"
            )
        bad = unclearable(
            self,
            foot_length=foot_length,
            thigh=thigh,
            shin=shin,
            hip_limits=hip_limits,
            knee_limits=knee_limits,
            heel_lift=heel_lift,
        )
        if bad:
            fam, piv, start, L, c = bad[0]
            raise TerrainError(
                f"{p}.families: {fam!r} up to {FAMILIES[fam].height[1]:.3f} m high cannot be cleared with pivot "
                f"{piv!r} (start {start:.3f} m, step length {L:.3f} m, centre {c:.3f} m): the heel "
                f"{heel_lift:.3f} m over its top is out of the leg's reach or joint limits"
            )


# [layout] terrain of the default model (configs/default.toml); the other TerrainSpec fields keep
# jaxexo.physics.terrain's defaults.
DEFAULT_TERRAIN = {"start_shift": [0.0, 0.12], "step_length": [0.55, 0.85]}


TERRAIN_KEYS = (
    "families",
    "weights",
    "start_shift",
    "step_length",
    "pivot",
    "near_margin",
    "far_margin",
)


def parse_terrain(path: str, v: Any) -> "TerrainSpec | None":
    """[layout] terrain: ``false`` (off: reset draws the obstacle mixture) or a table of TerrainSpec
    fields (families by name, weights, start_shift and step_length ranges in m, pivot weights,
    near/far margins in m): reset then draws a procedural obstacle family, its outline and its
    placement instead of the mixture. Held-out families are refused."""
    if v is None or v is False:
        return None
    if isinstance(v, TerrainSpec):
        return v
    if v is True:
        v = {}
    if not isinstance(v, dict):
        raise ConfigError(
            f"{path}: expected false or a table of {', '.join(TERRAIN_KEYS)}, got {v!r}"
        )
    unknown = sorted(set(v) - set(TERRAIN_KEYS))
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(TERRAIN_KEYS)})")
    kw = dict(v)
    if "families" in kw:
        f = kw["families"]
        if isinstance(f, str):
            f = [f]
        if not isinstance(f, (list, tuple)) or not all(isinstance(x, str) for x in f):
            raise ConfigError(f"{path}.families: expected a list of family names, got {f!r}")
        kw["families"] = tuple(f)
    if "weights" in kw:
        kw["weights"] = _vector(f"{path}.weights", kw["weights"], nonneg=True)
    if "pivot" in kw:
        kw["pivot"] = pivot_weights(f"{path}.pivot", kw["pivot"])
    for k, hi in (("start_shift", MAX_SHIFT), ("step_length", MAX_STEP_LENGTH)):
        if k in kw:
            kw[k] = _range(f"{path}.{k}", kw[k], nonneg=True, hi=hi)
    for k in ("near_margin", "far_margin"):
        if k in kw:
            kw[k] = _number(f"{path}.{k}", kw[k], positive=True, hi=MAX_SHIFT)
    try:
        return TerrainSpec(**kw, path=path)
    except TerrainError as e:
        raise ConfigError(str(e)) from None


def write_terrain(spec) -> Any:
    if spec is None:
        return False
    return {
        "families": list(spec.families),
        "weights": list(spec.weights),
        "start_shift": list(spec.start_shift),
        "step_length": list(spec.step_length),
        "pivot": list(spec.pivot),
        "near_margin": spec.near_margin,
        "far_margin": spec.far_margin,
    }


class TerrainLeaves(NamedTuple):
    """The terrain's EnvParams leaves (F families drawn; 0 for terrain off)."""

    terrain_ids: np.ndarray  # [F] int32 family ids
    terrain_cdf: np.ndarray  # [F] their cumulative probabilities
    terrain_start_shift: np.ndarray  # [2] m
    terrain_step_length: np.ndarray  # [2] m
    terrain_pivot_cdf: np.ndarray  # [3]
    terrain_margins: np.ndarray  # [2] m, near and far


def terrain_params(spec, cfg) -> TerrainLeaves:
    """The terrain description as EnvParams leaves. Off: ``terrain_ids`` has length 0, which
    jaxexo.physics.scenarios reads as a static (shape) switch back to the obstacle mixture."""
    f = lambda x: np.asarray(x, dtype=np.float32)  # noqa: E731
    if spec is None:
        return TerrainLeaves(
            terrain_ids=np.zeros((0,), np.int32),
            terrain_cdf=f(np.zeros((0,))),
            terrain_start_shift=f([0.0, 0.0]),
            terrain_step_length=f([0.0, 0.0]),
            terrain_pivot_cdf=cdf([1.0, 1.0, 1.0]),
            terrain_margins=f([0.0, 0.0]),
        )
    return TerrainLeaves(
        terrain_ids=spec.ids.astype(np.int32),
        terrain_cdf=f(spec.cdf),
        terrain_start_shift=f(spec.start_shift),
        terrain_step_length=f(spec.step_length),
        terrain_pivot_cdf=cdf(spec.pivot),
        terrain_margins=f([spec.near_margin, spec.far_margin]),
    )
