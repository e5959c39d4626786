"""TrajectoryGenerator: an exported policy (policy.npz) driven greedily in NumPy, smoothed and checked.

The rollout follows the training environment's rules exactly (jaxexo.physics.dynamics: the same move, goal,
mid-goal and observation functions, the same step limit and collision handling), with the greedy
action of the exported Q-network. Two loops share those rules:

- ``generate`` (one scene): the heel and the step counter are Python floats and the observation,
  which is affine in (heel y, heel z, time, visited) for a fixed scene, is folded into the network's
  first layer, so a step is a few small matmuls (see jaxexo.inference.network);
- ``generate_batch`` (many scenes): NumPy arrays over the scenes still moving, one batched network
  call per step.

The raw path is then smoothed (thesis 2.7, jaxexo.inference.smoothing) and checked on the smoothed
samples (jaxexo.inference.trajectory). If smoothing turns a collision-free raw path into a colliding
one, the generator retries with a quarter of the smoothing, then a sixteenth, then an interpolating
spline, then the raw polyline, and records which it used (``Trajectory.smoothing``, ``notes``).
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np

from jaxexo.physics import dynamics, geometry
from jaxexo.config import ConfigError, config_from_dict
from jaxexo.physics.dynamics import Scene, scalar
from jaxexo.inference import smoothing as sm
from jaxexo.inference.network import FoldedQNetwork, StepNetwork
from jaxexo.inference.trajectory import DEFAULT_DURATION, Trajectory, TrajectoryBatch, TrajectoryError, assemble
from jaxexo.storage.policy_file import PolicyFileError, QPolicy, load_policy

FALLBACK_FACTORS = (0.25, 1.0 / 16.0, 0.0)   # smoothing multipliers tried before the raw polyline


class TrajectoryGenerator:
    """Greedy trajectories from an exported Q-network. Build with ``TrajectoryGenerator.load(path)``."""

    def __init__(self, policy: QPolicy, config, source: str = "<policy>"):
        self.policy = policy
        self.config = config
        self.source = source
        self.np_params = dynamics.numpy_params(config)
        self.sp = dynamics.scalar_params(config)
        self.obs_mode = config.env.obs_mode
        self.max_steps = int(config.env.max_steps)
        self.terminate_on_collision = config.env.collision == "terminate"
        self.directions = [tuple(float(x) for x in d) for d in self.np_params.directions]
        self.net = FoldedQNetwork(policy)
        self.step_net = StepNetwork(self.net)
        self._linear = None
        self.epsilon = 0.0      # 0: greedy (the default; a device's generator must not explore)
        self._rng = None

    def exploring(self, epsilon: float, seed: int = 0) -> "TrajectoryGenerator":
        """A copy that acts epsilon-greedily (thesis 2.6 tests that way): each step a uniformly
        random action with probability ``epsilon``, from its own seeded stream (deterministic for a
        given seed and scenario order). For reproducing the thesis's test protocol only."""
        import copy

        eps = float(epsilon)
        if not 0.0 <= eps <= 1.0:
            raise ValueError(f"epsilon must be in [0, 1], got {epsilon!r}")
        out = copy.copy(self)
        out.epsilon, out._rng = eps, np.random.default_rng(seed)
        return out

    def _explore(self, greedy):
        """Replace greedy actions (an int or an array) by random ones with probability epsilon."""
        if self.epsilon <= 0.0:
            return greedy
        g = np.asarray(greedy)
        rand = self._rng.integers(len(self.directions), size=g.shape)
        pick = np.where(self._rng.uniform(size=g.shape) < self.epsilon, rand, g)
        return int(pick) if pick.ndim == 0 else pick

    @classmethod
    def load(cls, path: str | Path) -> "TrajectoryGenerator":
        """Read policy.npz (no pickle) and check that it is a policy this generator can drive."""
        policy = load_policy(path)
        meta = policy.metadata
        text = meta.get("config_toml")
        if not isinstance(text, str):
            raise PolicyFileError(f"{path}: metadata.config_toml is missing; cannot rebuild the environment")
        try:
            config = config_from_dict(tomllib.loads(text))
        except (tomllib.TOMLDecodeError, ConfigError) as e:
            raise PolicyFileError(f"{path}: metadata.config_toml is not a valid jaxexo config ({e})") from None
        obs_dim = 2 if config.env.obs_mode == "thesis" else 14 + config.env.shape_points
        if policy.obs_dim != obs_dim or meta.get("obs_dim") != obs_dim:
            raise PolicyFileError(f"{path}: the network takes {policy.obs_dim} inputs (metadata.obs_dim "
                                  f"{meta.get('obs_dim')!r}) but its config's {config.env.obs_mode!r} observation "
                                  f"has {obs_dim}")
        angles = meta.get("action_angles_rad")
        expected = np.arctan2(*dynamics.action_directions()[:, ::-1].T)
        if (not isinstance(angles, list) or len(angles) != len(expected)
                or not np.allclose(np.mod(np.asarray(angles, float) - expected + np.pi, 2 * np.pi) - np.pi, 0, atol=1e-9)):
            raise PolicyFileError(f"{path}: metadata.action_angles_rad does not match the 36 moves at k*10 deg")
        for key, value in (("length_scale", dynamics.LENGTH_SCALE),
                           ("thesis_obs_center", list(dynamics.THESIS_OBS_CENTER))):
            if meta.get(key) != value:
                raise PolicyFileError(f"{path}: metadata.{key} is {meta.get(key)!r}; this jaxexo builds "
                                      f"observations with {value!r}")
        return cls(policy, config, str(path))

    # Scenes -------------------------------------------------------------------------------------
    def scene(self, obstacle: geometry.Obstacle, pivot: str = "obstacle", pivot_y: float | None = None,
              start_y: float = 0.0, step_length: float = 0.70) -> Scene:
        """Validate one scenario (metres). ``pivot_y``, when given, overrides the ``pivot`` condition."""
        return dynamics.make_scene(obstacle, pivot if pivot_y is None else pivot_y, start_y, step_length,
                                   foot_length=self.config.kinematics.foot_length,
                                   shape_points=self.config.env.shape_points)

    def _scenes(self, obstacles, pivot, pivot_y, start_y, step_length) -> list[Scene]:
        return scenes_for(self.scene, obstacles, pivot, pivot_y, start_y, step_length)

    def _basis(self, scene: Scene) -> np.ndarray:
        """(5, D): the observation as c @ basis for c = (heel_y, heel_z, time, visited, 1).

        The observation is affine in c with coefficients that do not depend on the scene (they are
        1/LENGTH_SCALE, 1/max_steps, ...), so the linear rows are found once, from unit vectors,
        and only the origin row is computed per scene."""
        if self._linear is None:
            e = np.eye(5)    # rows: unit heel_y, heel_z, time, visited, then the origin
            obs = dynamics.observation(np, self.np_params, self.obs_mode, e[:, 0], e[:, 1], e[:, 2], e[:, 3],
                                       dynamics.stack_scenes([scene] * 5, np.float64))
            self._linear = obs[:4] - obs[4]
        z = np.zeros(1)
        origin = dynamics.observation(np, self.np_params, self.obs_mode, z, z, z, z,
                                      dynamics.stack_scenes([scene], np.float64))
        return np.vstack([self._linear, origin])

    # Rollouts -----------------------------------------------------------------------------------
    def rollout(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """Greedy raw path of one scene: heel points (M, 2) from the start, and the actions (M-1,)."""
        sp, step = self.sp, self.step_net
        step.set_scene(self._basis(scene))
        mid_y, mid_z = dynamics.mid_goal(scalar, sp, scene.center_y, scene.height)
        hy, hz, t, visited = float(scene.start_y), 0.0, 0, False
        pts, acts = [(hy, hz)], []
        while True:
            a = self._explore(step.greedy(hy, hz, t, 1.0 if visited else 0.0))
            hy, hz = dynamics.move_heel(scalar, sp, hy, hz, *self.directions[a])
            t += 1
            visited = visited or dynamics.in_mid_goal(scalar, sp, hy, hz, mid_y, mid_z)
            pts.append((hy, hz))
            acts.append(a)
            if dynamics.goal_reached(scalar, sp, hy, hz, scene.goal_y) or t >= self.max_steps:
                break
            if self.terminate_on_collision and self._touches(scene, np.array([[hy, hz]])):
                break
        return np.asarray(pts), np.asarray(acts, dtype=np.int64)


    def rollout_batch(self, scenes) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Greedy raw paths of many scenes at once (float32 NumPy, like the JAX environment)."""
        p = self.np_params
        lay = dynamics.stack_scenes(scenes, np.float32)
        b = len(scenes)
        dirs = p.directions
        hy = lay.start_y.copy()
        hz = np.zeros(b, np.float32)
        t = np.zeros(b, np.int32)
        visited = np.zeros(b, bool)
        mid_y, mid_z = dynamics.mid_goal(np, p, lay.center_y, lay.height)
        path = np.empty((self.max_steps + 1, b, 2), np.float32)
        acts = np.zeros((self.max_steps, b), np.int64)
        path[0, :, 0], path[0, :, 1] = hy, hz
        length = np.ones(b, np.int64)
        alive = np.arange(b)
        for k in range(self.max_steps):
            sub = _take(lay, alive)
            obs = dynamics.observation(np, p, self.obs_mode, hy[alive], hz[alive], t[alive], visited[alive], sub)
            a = self._explore(np.argmax(self.net.q(obs), axis=-1))
            ny, nz = dynamics.move_heel(np, p, hy[alive], hz[alive], dirs[a, 0], dirs[a, 1])
            hy[alive], hz[alive] = ny, nz
            t[alive] += 1
            visited[alive] |= dynamics.in_mid_goal(np, p, ny, nz, mid_y[alive], mid_z[alive])
            path[k + 1, alive, 0], path[k + 1, alive, 1] = ny, nz
            acts[k, alive] = a
            length[alive] += 1
            done = dynamics.goal_reached(np, p, ny, nz, sub.goal_y) | (t[alive] >= self.max_steps)
            if self.terminate_on_collision:
                c = geometry.foot_clearance(np, np.stack([ny, nz], -1), p.foot_length, sub.outline)
                done |= geometry.foot_collides(np, c)
            alive = alive[~done]
            if alive.size == 0:
                break
        paths = [path[: length[i], i].astype(np.float64) for i in range(b)]
        return paths, [acts[: length[i] - 1, i] for i in range(b)]

    # Trajectories ---------------------------------------------------------------------------------
    def _fallback(self, scene: Scene, raw: np.ndarray, n_points: int, smoothing: float):
        """A smoothed path touched the obstacle: when the raw path does not, retry with less smoothing
        (FALLBACK_FACTORS), then the raw polyline. Returns (path, smoothing used, notes), or None when
        the raw path itself touches the obstacle (smoothing is then kept and the checks report it)."""
        if self._touches(scene, raw):
            return None
        for f in FALLBACK_FACTORS:
            cand = sm.bspline_smooth(raw, n_points, smoothing * f)
            if not self._touches(scene, cand):
                return cand, smoothing * f, (f"smoothing {smoothing:g} m^2 made the foot touch the obstacle; "
                                             f"{smoothing * f:g} m^2 used",)
        return sm.linear_resample(raw, n_points), float("nan"), (
            "every smoothing made the foot touch the obstacle; the raw polyline is used",)

    def _finish(self, scenes, raws, n_points: int, smoothing: float, duration: float) -> TrajectoryBatch:
        """Smooth every raw path, check them all at once, and redo the few that smoothing made collide."""
        if smoothing > 0:
            paths = list(sm.smooth_paths(raws, n_points, smoothing))
            used = [smoothing] * len(raws)
        else:
            paths = [sm.linear_resample(r, n_points) for r in raws]
            used = [float("nan")] * len(raws)
        notes = [()] * len(raws)
        batch = assemble("rl", self.sp, scenes, raws, np.stack(paths), used, duration, notes)
        redo = []
        for i in np.flatnonzero(~batch.collision_free) if smoothing > 0 else ():
            fb = self._fallback(scenes[i], raws[i], n_points, smoothing)
            if fb is not None:
                redo.append((i, fb))
        if redo:
            idx = [i for i, _ in redo]
            sub = assemble("rl", self.sp, [scenes[i] for i in idx], [raws[i] for i in idx],
                           np.stack([fb[0] for _, fb in redo]), [fb[1] for _, fb in redo], duration,
                           [fb[2] for _, fb in redo])
            batch = batch.with_rows(idx, sub)
        return batch

    def _touches(self, scene: Scene, path: np.ndarray) -> bool:
        # Cheap exclusion first: a path that never comes below the obstacle's top within its extent
        # cannot touch it (the foot is horizontal).
        y, z = path[:, 0], path[:, 1]
        near = (z <= scene.height + 1e-6) & (y <= scene.center_y + 0.5 * scene.width + 1e-6) & (
            y + self.sp.foot_length >= scene.center_y - 0.5 * scene.width - 1e-6)
        if not near.any():
            return False
        c = geometry.foot_clearance(np, path[near], self.sp.foot_length, scene.outline)
        return bool(np.any(geometry.foot_collides(np, c)))

    def generate(self, obstacle: geometry.Obstacle, *, pivot: str = "obstacle", pivot_y: float | None = None,
                 start_y: float = 0.0, step_length: float = 0.70, n_points: int = sm.DEFAULT_POINTS,
                 smoothing: float = sm.DEFAULT_SMOOTHING, duration: float = DEFAULT_DURATION,
                 strict: bool = False) -> Trajectory:
        """One smoothed, checked trajectory (metres, radians, seconds). ``strict`` raises
        TrajectoryError instead of returning a trajectory that fails a check."""
        n_points, smoothing, duration = check_options(n_points, smoothing, duration)
        scene = self.scene(obstacle, pivot, pivot_y, start_y, step_length)
        raw, _ = self.rollout(scene)
        traj = self._finish([scene], [raw], n_points, smoothing, duration)[0]
        if strict and not traj.ok:
            raise TrajectoryError(traj)
        return traj

    def generate_batch(self, obstacles, *, pivot="obstacle", pivot_y=None, start_y=0.0, step_length=0.70,
                       n_points: int = sm.DEFAULT_POINTS, smoothing: float = sm.DEFAULT_SMOOTHING,
                       duration: float = DEFAULT_DURATION, strict: bool = False) -> TrajectoryBatch:
        """Trajectories for many scenarios; every option is one value or one per obstacle."""
        n_points, smoothing, duration = check_options(n_points, smoothing, duration)
        scenes = self._scenes(obstacles, pivot, pivot_y, start_y, step_length)
        raws, _ = self.rollout_batch(scenes)
        batch = self._finish(scenes, raws, n_points, smoothing, duration)
        if strict and not batch.ok.all():
            raise TrajectoryError(batch[int(np.argmin(batch.ok))])
        return batch


def scenes_for(make, obstacles, pivot, pivot_y, start_y, step_length) -> list[Scene]:
    """Scenes for many obstacles with ``make(obstacle, pivot, pivot_y, start_y, step_length)``; every
    option is one value for all or one per obstacle (shared by every generator's generate_batch)."""
    obstacles = list(obstacles)
    n = len(obstacles)
    if n == 0:
        raise ValueError("obstacles: need at least one scenario")

    def per(name, v):
        if np.ndim(v) == 0 or isinstance(v, str):
            return [v] * n
        v = list(v)
        if len(v) != n:
            raise ValueError(f"{name}: {len(v)} values for {n} obstacles")
        return v

    return [make(o, p, py, s, sl) for o, p, py, s, sl in zip(
        obstacles, per("pivot", pivot), per("pivot_y", pivot_y), per("start_y", start_y),
        per("step_length", step_length))]


def _take(lay, idx):
    return type(lay)(**{k: v[idx] for k, v in vars(lay).items()})


def check_options(n_points, smoothing, duration):
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 2:
        raise ValueError(f"n_points must be an integer >= 2, got {n_points!r}")
    smoothing = geometry._finite("smoothing", smoothing)
    if smoothing < 0:
        raise ValueError(f"smoothing must be >= 0 (m^2), got {smoothing}")
    return int(n_points), smoothing, geometry._finite_positive("duration", duration)
