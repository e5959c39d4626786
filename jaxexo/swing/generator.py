"""The generator interface, written once: ``generate``, ``generate_batch``, ``at_clearance`` and
``replan`` of every swing generator (the RL policy, CFFTG, any other). A generator supplies only its
planning step (``plan_batch``, and ``plan_swing`` where one swing is planned otherwise) and its
continuation from a mid-air foot state (``continue_from``); it is configured by construction
(``with_options`` returns a new one) and found by name (jaxexo.inference.registry).
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from typing import ClassVar

import numpy as np

from jaxexo.physics import geometry
from jaxexo.physics.scene import (
    DEFAULT_PIVOT,
    DEFAULT_START_Y,
    DEFAULT_STEP_LENGTH,
    Scene,
    check_clearance,
    make_scene,
)
from jaxexo.storage.policy_check import load_checked
from jaxexo.swing import timing
from jaxexo.swing.options import GenerateOptions, SwingOptions
from jaxexo.swing.replan import checked_obstacle_scene, checked_switch, continue_swing, foot_state
from jaxexo.swing.trajectory import Trajectory, TrajectoryBatch

# generate's options that a replan keeps from the swing (its scene's pivot, start and goal)
_SCENE_OPTIONS = ("pivot", "pivot_y", "start_y", "step_length")


class SwingGenerator:
    """A swing generator for a jaxexo ``config`` (its legs, margins and limits; ``sp``: its scalar
    parameter view at the generator's clearance). Subclasses set ``name`` (the method label its swings
    carry), ``options_type`` (what its ``generate`` takes) and ``where`` (how messages name its
    methods), take ``clearance`` and ``defaults`` keywords and write ``plan_batch`` and
    ``continue_from``."""

    name: ClassVar[str] = ""
    options_type: ClassVar[type[SwingOptions]] = SwingOptions
    where: ClassVar[str] = ""
    needs_policy: ClassVar[bool] = False  # built from a policy file only (the RL generator)
    # why it does not take an option others' generate takes (the command line's refusal)
    not_taken: ClassVar[dict[str, str]] = {}
    config: object
    sp: object
    defaults: SwingOptions  # generate's options where a call gives none (``with_defaults``)

    # Construction ----------------------------------------------------------------------------
    def __new__(cls, *args, **kwargs):
        self = super().__new__(cls)
        self._made = (args, kwargs)  # the construction ``with_options`` repeats with changes
        return self

    @classmethod
    def from_config(cls, config, **settings) -> "SwingGenerator":
        """This generator for ``config`` (a jaxexo Config), with ``settings`` (its constructor's)."""
        return cls(config, **settings)

    @classmethod
    def from_policy(cls, path, **settings) -> "SwingGenerator":
        """This generator with the kinematics of an exported policy's config (read and checked as the
        RL generator reads it)."""
        return cls.from_config(load_checked(path)[1], **settings)

    def with_options(self, **changes) -> "SwingGenerator":
        """A new generator: this one's construction with ``changes`` (its constructor's keywords)."""
        args, kwargs = self._made
        return type(self)(*args, **{**kwargs, **changes})

    def with_defaults(self, **fields) -> "SwingGenerator":
        """A new generator whose ``generate`` / ``generate_batch`` / ``replan`` take ``fields``
        (``options_type``'s) where a call gives no options record."""
        return self.with_options(defaults=replace(self.defaults, **fields))

    @classmethod
    def takes(cls, option: str) -> bool:
        """Whether ``generate`` takes the option ``option`` (a field of ``options_type``)."""
        return option in {f.name for f in dataclasses.fields(cls.options_type)}

    @classmethod
    def why_not(cls, option: str) -> str:
        """Why ``generate`` does not take ``option``."""
        return cls.not_taken.get(option, f"the {cls.name} generator does not take it")

    def at_clearance(self, clearance: float | None) -> "SwingGenerator":
        """This generator for swings that must keep ``clearance`` (m; None: the config's
        env.min_clearance, this generator itself; refused below it or above MAX_CLEARANCE)."""
        c = check_clearance(clearance, self.config.env.min_clearance)
        return self if c is None else self.with_options(clearance=c)

    def fallback_generator(self) -> "SwingGenerator | None":
        """The generator whose swing stands in for one of this generator's that is not safe, when
        the options' ``fallback`` asks for it (None: no fallback)."""
        return None

    @property
    def fallback_label(self) -> str:
        """The method label of this generator's swing standing in for another's."""
        return f"{self.name}-fallback"

    def describe(self, traj: Trajectory) -> str:
        """How ``traj`` (one of this generator's swings) was made, as ``jaxexo generate`` says it."""
        return f"{traj.method} path"

    # Scenes -----------------------------------------------------------------------------------
    def scene(
        self,
        obstacle: geometry.Obstacle,
        pivot: str | float | None = None,
        pivot_y: float | None = None,
        start_y: float = DEFAULT_START_Y,
        step_length: float = DEFAULT_STEP_LENGTH,
    ) -> Scene:
        """Validate one scenario (metres) for the config's foot length and shape descriptor.
        ``pivot_y``, when given, overrides the ``pivot`` condition."""
        return make_scene(
            obstacle,
            pivot_of(pivot, pivot_y),
            start_y,
            step_length,
            foot_length=self.config.kinematics.foot_length,
            shape_points=self.config.env.shape_points,
        )

    def scenes(self, obstacles, options: SwingOptions) -> list[Scene]:
        """Scenes of many obstacles; each of ``options``' scene fields is one value for all or one
        per obstacle."""
        obstacles = _obstacle_list(obstacles)
        n = len(obstacles)

        def per(name, v):
            if np.ndim(v) == 0 or isinstance(v, str):
                return [v] * n
            v = list(v)
            if len(v) != n:
                raise ValueError(f"{name}: {len(v)} values for {n} obstacles")
            return v

        columns = [per(k, v) for k, v in zip(SwingOptions.SCENE_FIELDS, options.scene_args)]
        return [self.scene(o, *args) for o, *args in zip(obstacles, *columns)]

    # The planning step (each generator's) -----------------------------------------------------
    def plan_batch(self, scenes: list[Scene], o: SwingOptions) -> TrajectoryBatch:
        """Checked trajectories [B] of validated scenes with the options ``o``."""
        raise NotImplementedError

    def plan_swing(self, scene: Scene, o: SwingOptions) -> Trajectory:
        """One checked trajectory of a validated scene (``plan_batch`` of one, unless overridden)."""
        return self.plan_batch([scene], o)[0]

    def continue_from(self, scene: Scene, state, o, swing_scene: Scene) -> Trajectory:
        """The heel path from the foot state ``state`` (jaxexo.swing.replan.FootState) over
        ``scene`` to its goal, checked on ``scene`` (``swing_scene``: the swing's own), with the
        options ``o`` (a GenerateOptions)."""
        raise NotImplementedError

    # The interface ----------------------------------------------------------------------------
    def options(self, options, overrides: dict, method: str, kind=None) -> SwingOptions:
        """``options`` (None: ``defaults``) with ``overrides`` replacing its fields, as ``kind``
        (default ``options_type``) checked once, an error naming ``method``."""
        kind = kind or self.options_type
        return kind.given(self.defaults if options is None else options, overrides, method)

    def generate(
        self, obstacle: geometry.Obstacle, options: SwingOptions | None = None, **overrides
    ) -> Trajectory:
        """One checked trajectory (metres, radians, seconds) for ``options`` (``options_type``),
        whose fields the keywords replace: ``generate(obstacle, pivot="between")``. ``strict``
        raises TrajectoryError instead of returning a trajectory that fails a check;
        ``clearance`` (m): the margin the swing keeps (``at_clearance``)."""
        o = self.options(options, overrides, self.where + "generate")
        gen = self.at_clearance(o.clearance)
        return o.checked(gen.plan_swing(gen.scene(obstacle, *o.scene_args), o))

    def generate_batch(
        self, obstacles, options: SwingOptions | None = None, **overrides
    ) -> TrajectoryBatch:
        """Trajectories for many scenarios, with ``generate``'s options; each scene field (pivot,
        pivot_y, start_y, step_length) is one value or one per obstacle. ``strict`` raises
        TrajectoryError on the first swing that fails a check."""
        o = self.options(options, overrides, self.where + "generate_batch")
        gen = self.at_clearance(o.clearance)
        return o.checked(gen.plan_batch(gen.scenes(obstacles, o), o))

    def replan(self, swing, obstacle, options=None, *, at, **overrides):
        """``swing`` (a TimedSwing) replanned in flight at t = ``at`` (s) over ``obstacle``: kept on
        [0, at], continued from the foot's state there (``continue_from``) to the same goal, C2 at
        ``at``, timed within the swing's limits, judged whole against the new obstacle
        (jaxexo.swing.replan; docs/replanning.md). Options as ``generate``'s (not the scene's) and
        ``rate``; where the joined swing is not safe and the options' fallback asks for it, the
        ``fallback_generator``'s continuation from the same state when that swing is; ``strict``
        raises TrajectoryError for a swing that is not safe."""
        where = self.where + "replan"
        for name in _SCENE_OPTIONS:
            if name in overrides:
                raise TypeError(
                    f"{name}: not an option of {where}: a replanned swing keeps the pivot, start "
                    "and goal of the swing it continues"
                )
        overrides = dict(overrides)
        rate = overrides.pop("rate", None)
        o = self.options(options, overrides, where, GenerateOptions)
        t = checked_switch(swing, at, self.config)
        if rate is not None:
            timing.check_rate(rate)
        g = self.at_clearance(o.clearance)
        state = foot_state(swing, t)
        scene = checked_obstacle_scene(g, swing, obstacle, state)
        cont = g.continue_from(scene, state, o, swing.scene)
        new = continue_swing(swing, cont, at=t, sp=g.sp, rate=rate)
        fb = None if new.ok or o.fallback is None else g.fallback_generator()
        if fb is not None and not cont.method.startswith(fb.name):
            other = fb.continue_from(scene, state, o, swing.scene)
            # Only a continuation that passes its own checks can give a joined swing that passes.
            alt = other.ok and continue_swing(
                swing, replace(other, method=fb.fallback_label), at=t, sp=g.sp, rate=rate
            )
            if alt and alt.ok:
                note = f"the {cont.method} continuation joined was not safe: {new.reasons[0]}"
                new = replace(alt, notes=alt.notes + (note,))
        return o.checked(new)


def pivot_of(pivot, pivot_y):
    """The scene's pivot: a condition (default DEFAULT_PIVOT) or ``pivot_y`` in metres, not both."""
    if pivot_y is None:
        return DEFAULT_PIVOT if pivot is None else pivot
    if pivot is not None:
        raise ValueError(
            f"pivot, pivot_y: give one of them (a condition or a y in metres), got pivot={pivot!r} "
            f"and pivot_y={pivot_y!r}"
        )
    return pivot_y


def _obstacle_list(obstacles) -> list:
    """``obstacles`` as a non-empty list (TypeError for one Obstacle or not a sequence)."""
    if isinstance(obstacles, geometry.Obstacle):
        raise TypeError(
            "obstacles: expected a list of Obstacle objects, got one Obstacle (use generate() for "
            "one scenario, or pass [obstacle])"
        )
    try:
        obstacles = list(obstacles)
    except TypeError:
        raise TypeError(
            f"obstacles: expected a list of Obstacle objects, got {type(obstacles).__name__}"
        ) from None
    if not obstacles:
        raise ValueError("obstacles: need at least one scenario")
    return obstacles
