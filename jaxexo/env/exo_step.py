"""ExoStepEnv: the swing heel of a lower-limb exoskeleton stepping over a low obstacle (thesis
ch. 2), in pure JAX on gymnax's ``Environment`` (its auto-reset ``step`` and ``reset``; ``step_env``
and ``reset_env`` here). State, layout and params are flax.struct pytrees, so it jits and vmaps over
episodes and configs; the rules come from jaxexo.physics. How it behaves:
docs/training.md#the-environment.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct
from gymnax.environments import spaces
from gymnax.environments.environment import Environment

from jaxexo.config import Config
from jaxexo.env.params import EnvParams
from jaxexo.physics import actions, changes, geometry, scenarios, transition
from jaxexo.physics.actions import LENGTH_SCALE, NUM_ACTIONS, THESIS_OBS_CENTER  # noqa: F401 (re-exported)
from jaxexo.physics.scene import Scene as Layout  # one episode's scene: physics's one scene record
from jaxexo.physics.scene import make_scene
from jaxexo.shield import compact, make_shield, rule

# Every observation lies within +-OBS_BOUND (world bounds of a few metres over LENGTH_SCALE).
OBS_BOUND = 10.0
# Fresh scenes drawn per round of step_batch's auto-reset, as a fraction of the batch (episodes last
# tens of steps, so a few per cent of the environments end at a step).
RESET_BUFFER_FRACTION = 0.0625


@struct.dataclass
class ObstacleChange:
    """The obstacle an episode switches to ([env] obstacle_change): ``layout`` from step count ``at``
    on (-1: never), unless the foot is too close to it then (jaxexo.physics.changes.fires)."""

    at: jnp.ndarray
    layout: Layout


@struct.dataclass
class EnvState:
    heel: jnp.ndarray  # (2,) swing heel (y, z), m
    time: jnp.ndarray  # steps taken this episode (gymnax name)
    visited_mid: jnp.ndarray  # bool: the heel has passed through the mid-goal box
    max_y: jnp.ndarray  # the heel's largest y this episode (backward motion)
    last_action: jnp.ndarray  # the move just made (-1 at the start): the shield never undoes it
    layout: Layout
    # With [env] obstacle_change on: the change this episode may see; None (no leaves) when off, so
    # that the environment without it is the program it was before the option existed.
    change: ObstacleChange | None = None


class ExoStepEnv(Environment):
    """The stepping environment. Static settings (shapes) live on the instance; the rest in EnvParams.

    ``obs_mode``: ``"thesis"`` observes the heel's (y, z) only, as the thesis network;
    ``"conditioned"`` also observes the scene (obstacle extents and shape, goal, mid-goal and pivot
    relative to the heel, progress), so one policy can serve every layout."""

    def __init__(self, config: Config | None = None):
        self.config = config if config is not None else Config()
        self.obs_mode = self.config.env.obs_mode
        self.shape_points = self.config.env.shape_points
        self.max_vertices = self.config.outline_vertices
        # static: without the shield no mask is computed at all (its cost is a swept check per move)
        self.shield = bool(self.config.env.shield)
        # static: episodes whose obstacle changes mid-swing (jaxexo.physics.changes)
        self.obstacle_change = self.config.env.obstacle_change is not None
        self._default_params = None

    # gymnax-style properties --------------------------------------------------------------
    @property
    def default_params(self) -> EnvParams:
        if self._default_params is None:
            self._default_params = EnvParams.from_config(self.config)
        return self._default_params

    @property
    def name(self) -> str:
        return "ExoStep-v0"

    @property
    def num_actions(self) -> int:
        return NUM_ACTIONS

    @property
    def obs_dim(self) -> int:
        return actions.obs_dim(self.obs_mode, self.shape_points)

    def action_space(self, params: EnvParams | None = None):
        return spaces.Discrete(NUM_ACTIONS)

    def observation_space(self, params: EnvParams | None = None):
        # Observations are lengths / LENGTH_SCALE inside the world bounds, flags and progress in [0, 1].
        return spaces.Box(-OBS_BOUND, OBS_BOUND, (self.obs_dim,), jnp.float32)

    # Layout sampling ----------------------------------------------------------------------
    def sample_layout(self, key, params: EnvParams) -> Layout:
        """Draw one scene from the layout distribution in params (obstacle kind and size, position
        jitter, pivot condition, start shift, step length) by jaxexo.physics.scenarios, the one
        scenario generator: the scene of the key's two words, which NumPy tools draw identically."""
        return self.layout_from_uniforms(self._uniforms(key, params, 0), params)

    @staticmethod
    def _uniforms(key, params: EnvParams, extra: int):
        """The scene's uniform numbers and ``extra`` more after them (the first ones are the same
        whatever ``extra``: Threefry of the counter)."""
        words = jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key
        n = scenarios.n_uniforms(params) + extra
        return scenarios.uniforms(jnp, words[..., 0], words[..., 1], n)

    def change_from_uniforms(self, layout: Layout, u, params: EnvParams) -> ObstacleChange:
        """The obstacle change of an episode on ``layout`` from uniform numbers u
        (..., changes.N_UNIFORMS) (jaxexo.physics.changes.changed_layout)."""
        c = changes.changed_layout(jnp, params, layout, u)
        return ObstacleChange(
            at=c.at,
            layout=layout._replace(
                outline=c.outline,
                shape=c.shape,
                center_y=c.center_y,
                width=c.width,
                height=c.height,
            ),
        )

    def no_change(self, layout: Layout) -> ObstacleChange:
        """An episode on ``layout`` whose obstacle never changes."""
        return ObstacleChange(at=jnp.full(jnp.shape(layout.center_y), -1, jnp.int32), layout=layout)

    def layout_from_uniforms(self, u, params: EnvParams, kind=None, pivot_kind=None) -> Layout:
        """The scene of uniform numbers u (..., scenarios.n_uniforms(params))
        (jaxexo.physics.scenarios.layout_from_uniforms; procedural terrain when the config has it)."""
        t = self.config.layout.terrain  # static: evaluate only the outlines of its families
        return scenarios.layout_from_uniforms(
            jnp, params, u, kind, pivot_kind, None if t is None else t.families
        )

    def init_state(
        self, layout: Layout, params: EnvParams, change: ObstacleChange | None = None
    ) -> tuple[jnp.ndarray, EnvState]:
        """Start an episode on a given layout: the heel on the ground at the start. With [env]
        obstacle_change on, ``change`` is the obstacle it switches to (None: it never does); off,
        ``change`` must be None."""
        if self.obstacle_change and change is None:
            change = self.no_change(layout)
        if change is not None and not self.obstacle_change:
            raise ValueError("change: this environment's config has env.obstacle_change off")
        heel = jnp.stack([layout.start_y, jnp.zeros_like(layout.start_y)])
        state = EnvState(
            heel=heel,
            time=jnp.asarray(0, jnp.int32),
            visited_mid=jnp.asarray(False),
            max_y=heel[0],
            last_action=jnp.asarray(-1, jnp.int32),
            layout=layout,
            change=change,
        )
        return self.get_obs(state, params), state

    def layout_for(
        self,
        obstacle: geometry.Obstacle,
        pivot: str | float = "obstacle",
        start_y: float = 0.0,
        step_length: float = 0.70,
        kind: int = -1,
    ) -> Layout:
        """A fixed layout from an Obstacle, for evaluation on chosen scenes (validated by
        jaxexo.physics.scene.make_scene, as the NumPy generator's scenes are).

        ``pivot`` is one of PIVOT_CONDITIONS or a pivot heel y in metres; ``kind`` tags the layout
        for per-kind statistics."""
        sc = make_scene(
            obstacle,
            pivot,
            start_y,
            step_length,
            foot_length=self.config.kinematics.foot_length,
            max_vertices=self.max_vertices,
            shape_points=self.shape_points,
        )
        f = lambda x: jnp.asarray(x, dtype=jnp.float32)  # noqa: E731
        return Layout(
            outline=f(sc.outline),
            shape=f(sc.shape),
            center_y=f(sc.center_y),
            width=f(sc.width),
            height=f(sc.height),
            kind=jnp.asarray(kind, jnp.int32),
            pivot_kind=jnp.asarray(sc.pivot_kind, jnp.int32),
            pivot_y=f(sc.pivot_y),
            start_y=f(sc.start_y),
            goal_y=f(sc.goal_y),
        )

    # gymnax transitions (``step`` and ``reset``: gymnax's, with its auto-reset) -------------------
    def reset_env(self, key, params: EnvParams):
        if not self.obstacle_change:
            return self.init_state(self.sample_layout(key, params), params)
        # The scene's numbers as without the change, the change's after them.
        u = self._uniforms(key, params, changes.N_UNIFORMS)
        n = scenarios.n_uniforms(params)
        layout = self.layout_from_uniforms(u[..., :n], params)
        return self.init_state(
            layout, params, self.change_from_uniforms(layout, u[..., n:], params)
        )

    def advance(
        self, state: EnvState, action, params: EnvParams
    ) -> tuple[jnp.ndarray, EnvState, transition.Step]:
        """One step without reset (deterministic): the observation, the next state and the step's
        record (jaxexo.physics.transition.step: reward, flags, info)."""
        lay, heel = state.layout, state.heel
        at = (heel[0], heel[1], params.directions[action], state.time, state.visited_mid, lay)
        kw = {"max_y": state.max_y, "action": action, "last_action": state.last_action}
        out = transition.step(jnp, params, *at, max_steps=params.max_steps_in_episode, **kw)
        heel = out.info.heel
        if state.change is not None:  # from this step on, the changed obstacle (if it fires)
            new = state.change.layout
            fire = changes.fires(jnp, params, heel, out.time, state.change.at, new.outline)
            lay = jax.tree.map(lambda a, b: jnp.where(fire, a, b), new, lay)
        new_state = EnvState(
            heel=heel,
            time=out.time,
            visited_mid=out.visited_mid,
            max_y=out.max_y,
            last_action=jnp.asarray(action, jnp.int32),
            layout=lay,
            change=state.change,
        )
        return self.get_obs(new_state, params), new_state, out

    def step_env(self, key, state: EnvState, action, params: EnvParams):
        """gymnax's step without reset: (obs, state, reward, terminated, info) with the info
        the step's (jaxexo.physics.transition.StepInfo) by field name."""
        obs, state, out = self.advance(state, action, params)
        return obs, state, out.reward, out.terminated, out.info._asdict()

    def step_batch(self, reset_keys, states: EnvState, actions, params: EnvParams | None = None):
        """The trainer's step of a batch of N environments (reset keys, states and actions with a
        leading N): ``(obs, state, step, final_obs)`` with ``step`` the transition's record
        (transition.Step [N]) and ``final_obs`` the finished episodes' last observations (for
        bootstrapping through truncation). Equal to ``jax.vmap(step)`` bit for bit (given the keys that
        ``step`` splits off for its reset) at a fraction of the cost: the auto-reset draws fresh scenes
        only for the environments whose episode ended (jaxexo.shield.compact), where ``step`` under
        vmap draws one for every environment at every step (for procedural terrain, most of a step's
        time: docs/training.md)."""
        params = self.default_params if params is None else params
        n = actions.shape[0]
        obs_st, state_st, out = jax.vmap(self.advance, in_axes=(0, 0, None))(
            states, actions, params
        )

        def fresh(idx):
            return jax.vmap(self.reset_env, in_axes=(0, None))(reset_keys[idx], params)

        obs, state = compact.compacted(
            out.terminated | out.truncated,
            fresh,
            (obs_st, state_st),
            compact.buffer_size(n, RESET_BUFFER_FRACTION),
        )
        return obs, state, out, obs_st

    def action_mask(self, state: EnvState, params: EnvParams | None = None):
        """(NUM_ACTIONS,) bool: the moves the agent may choose in ``state``
        (jaxexo.shield.rule.admissible_moves); every move without the shield."""
        params = self.default_params if params is None else params
        if not self.shield:
            return jnp.ones(NUM_ACTIONS, bool)
        return rule.admissible_moves(
            jnp,
            params,
            state.heel[0],
            state.heel[1],
            state.layout,
            over_moves=lambda f, xs: jax.lax.map(lambda x: f(*x), xs),
            last_action=state.last_action,
        )

    def action_masks(self, states: EnvState, params: EnvParams | None = None):
        """(N, NUM_ACTIONS) bool: ``action_mask`` of a batch of N states (leading axis), the same
        decisions at a fraction of the cost: the exact swept check only for the moves a cheap bound
        leaves open (jaxexo.shield's JAX form). The trainer's mask, every step."""
        params = self.default_params if params is None else params
        n = states.heel.shape[0]
        if not self.shield:
            return jnp.ones((n, NUM_ACTIONS), bool)
        return make_shield("jax", params).admissible(
            states.heel[:, 0],
            states.heel[:, 1],
            states.layout,
            last_action=states.last_action,
        )

    # Observations ---------------------------------------------------------------------------
    def get_obs(self, state: EnvState, params: EnvParams):
        return actions.observation(
            jnp,
            params,
            self.obs_mode,
            state.heel[0],
            state.heel[1],
            state.time,
            state.visited_mid,
            state.layout,
        )
