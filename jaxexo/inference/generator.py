"""TrajectoryGenerator: an exported policy (policy.npz) driven greedily in NumPy, finished and checked.

The rollout follows the training environment's rules (jaxexo.physics) with the exported Q-network's
greedy action, shielded (jaxexo.shield's scalar form for one swing, its rows form for a batch); the
raw path is finished (jaxexo.swing.finish) and, with ``fallback="cfftg"``, a failing swing is
replaced by CFFTG's (``replace_failures``). Method: docs/generation.md.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from jaxexo.config import numpy_params, scalar_params
from jaxexo.inference import blas
from jaxexo.inference.network import FoldedQNetwork, StepNetwork
from jaxexo.physics import actions, geometry, swept, transition
from jaxexo.physics.scene import Scene, check_clearance, stack_scenes, with_clearance
from jaxexo.physics.transition import scalar
from jaxexo.shield import ShieldStats, make_shield
from jaxexo.shield.rows import take_rows
from jaxexo.storage.policy_check import check_policy_legs, load_checked
from jaxexo.storage.policy_file import QPolicy
from jaxexo.swing import smoothing as sm
from jaxexo.swing.continuation import check_state, policy_clock
from jaxexo.swing.finish import PathFinisher
from jaxexo.swing.generator import SwingGenerator
from jaxexo.swing.options import (
    GenerateOptions,
    check_duration,
    check_fallback,
    check_points,
    check_smoothing,
)
from jaxexo.swing.trajectory import DEFAULT_DURATION, Trajectory, TrajectoryBatch


class _PolicyParts:
    """What a generator derives from its policy and config alone, shared by every generator
    ``with_options`` makes from it: the parameter views at the config's clearance, the folded
    network and its one-step form, the observation's linear rows (``_basis``, found once) and the
    shield's statistics."""

    def __init__(self, policy: QPolicy, config, source: str):
        check_policy_legs(policy, config, source)
        self.np_params = numpy_params(config)
        self.sp = scalar_params(config)
        self.net = FoldedQNetwork(policy)
        self.step_net = StepNetwork(self.net)
        self.linear = None
        self.shield_stats = ShieldStats()  # the fast shield's steps, and those it could not decide


class TrajectoryGenerator(SwingGenerator):
    """Greedy trajectories from an exported Q-network. Build with ``TrajectoryGenerator.load(path)``;
    configure with ``with_options`` (a new generator): ``clearance`` (m; None: env.min_clearance;
    ``at_clearance``), ``epsilon`` and ``seed`` (``exploring``), ``exact`` (``plain_reference``),
    ``clearing`` (the requested spline corrected where it cuts the margin, jaxexo.swing.clearing,
    before any smaller smoothing is tried; False: the candidates and retries alone),
    ``batch_blas_threads`` (BLAS threads for generate_batch, jaxexo.inference.blas: default threads
    were 4x slower on a busy 2-core machine; None leaves the process's BLAS as it is) and
    ``defaults`` (generate's options where a call gives none)."""

    name = "rl"
    options_type = GenerateOptions
    needs_policy = True

    def __init__(
        self,
        policy: QPolicy,
        config,
        source: str = "<policy>",
        *,
        clearance: float | None = None,
        epsilon: float = 0.0,
        seed: int = 0,
        exact: bool = False,
        clearing: bool = True,
        batch_blas_threads: int | None = 1,
        defaults: GenerateOptions | None = None,
        parts: _PolicyParts | None = None,
    ):
        self._parts = _PolicyParts(policy, config, source) if parts is None else parts
        self.policy, self.config, self.source = policy, config, source
        self.clearance = check_clearance(clearance, config.env.min_clearance)
        self.np_params = with_clearance(self._parts.np_params, self.clearance)
        self.sp = with_clearance(self._parts.sp, self.clearance)
        self.net, self.step_net = self._parts.net, self._parts.step_net
        self.shield_stats = self._parts.shield_stats
        self.epsilon = float(epsilon)
        if not 0.0 <= self.epsilon <= 1.0:
            raise ValueError(f"epsilon must be in [0, 1], got {epsilon!r}")
        # 0: greedy (the default; a device's generator must not explore)
        self._rng = np.random.default_rng(seed) if self.epsilon > 0.0 else None
        self._exact, self.clearing = bool(exact), bool(clearing)
        self.batch_blas_threads = batch_blas_threads
        self.defaults = GenerateOptions() if defaults is None else defaults
        self.obs_mode = config.env.obs_mode
        self.max_steps = int(config.env.max_steps)
        self.terminate_on_collision = config.env.collision == "terminate"
        self.directions = [tuple(float(x) for x in d) for d in self.np_params.directions]
        self._shields = {}  # the shield's NumPy forms by kind (``_shield``)
        self._cfftg = None  # built on the first fallback (its constants cost ~ms to derive)
        self.shield = bool(config.env.shield)
        # The spline's smoothing when a call does not give one (m^2, thesis 2.7's s).
        self.smoothing = model_smoothing(
            config.env.shield_clearance, config.env.min_clearance, self.shield, config.env.step_size
        )

    def with_options(self, **changes) -> "TrajectoryGenerator":
        """A new generator, this one's construction with ``changes`` (the constructor's keywords),
        sharing its policy's network and statistics."""
        return super().with_options(parts=self._parts, **changes)

    def exploring(self, epsilon: float, seed: int = 0) -> "TrajectoryGenerator":
        """A generator that acts epsilon-greedily (thesis 2.6 tests that way): each step a uniformly
        random action with probability ``epsilon``, from its own seeded stream (deterministic for a
        given seed and scenario order). For reproducing the thesis's test protocol only."""
        return self.with_options(epsilon=epsilon, seed=seed)

    def _explore(self, greedy, mask=None):
        """Replace greedy actions (an int or an array) by random ones with probability epsilon (uniform
        over the admissible moves ``mask`` (..., A) with the shield)."""
        if self.epsilon <= 0.0:
            return greedy
        g = np.asarray(greedy)
        if mask is None:
            rand = self._rng.integers(len(self.directions), size=g.shape)
        else:  # the k-th admissible move, k uniform
            m = np.asarray(mask).reshape(g.shape + (-1,))
            k = np.floor(self._rng.uniform(size=g.shape) * m.sum(-1)).astype(np.int64)
            rand = np.argmax(np.cumsum(m, axis=-1) > k[..., None], axis=-1)
        pick = np.where(self._rng.uniform(size=g.shape) < self.epsilon, rand, g)
        return int(pick) if pick.ndim == 0 else pick

    @classmethod
    def from_policy(cls, path: str | Path, **settings) -> "TrajectoryGenerator":
        """Read policy.npz (no pickle) and check that it is a policy this generator can drive."""
        policy, config = load_checked(path)
        return cls(policy, config, str(path), **settings)

    load = from_policy

    @classmethod
    def from_config(cls, config, **settings):
        raise TypeError("the RL generator needs a trained policy: TrajectoryGenerator.load(path)")

    # Scenes (``scene``: SwingGenerator's) --------------------------------------------------------
    def _basis(self, scene: Scene) -> np.ndarray:
        """(5, D): the observation as c @ basis for c = (heel_y, heel_z, time, visited, 1).

        The observation is affine in c with coefficients that do not depend on the scene (they are
        1/LENGTH_SCALE, 1/max_steps, ...), so the linear rows are found once, from unit vectors,
        and only the origin row is computed per scene."""
        if self._parts.linear is None:
            e = np.eye(5)  # rows: unit heel_y, heel_z, time, visited, then the origin
            obs = actions.observation(
                np,
                self.np_params,
                self.obs_mode,
                e[:, 0],
                e[:, 1],
                e[:, 2],
                e[:, 3],
                stack_scenes([scene] * 5, np.float64),
            )
            self._parts.linear = obs[:4] - obs[4]
        z = np.zeros(1)
        origin = actions.observation(
            np,
            self.np_params,
            self.obs_mode,
            z,
            z,
            z,
            z,
            stack_scenes([scene], np.float64),
        )
        return np.vstack([self._parts.linear, origin])

    # Rollouts -----------------------------------------------------------------------------------
    def rollout(self, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
        """Greedy raw path of one scene: heel points (M, 2) from the start, and the actions (M-1,).

        With the shield, a greedy rollout checks the moves one at a time in order of Q until one is
        admissible (jaxexo.shield.scalar: the same move as the full mask, which it computes
        instead on the rare steps it cannot decide); ``plain_reference`` computes the full mask
        every step."""
        return self.rollout_from(scene, heel=(float(scene.start_y), 0.0), steps=0, visited=False)

    def rollout_from(
        self, scene: Scene, *, heel: tuple[float, float], steps: int, visited: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """``rollout``'s greedy raw path from any heel (y, z) (m, Python floats, on no lattice), with
        the policy's clock at ``steps`` moves made and the mid-goal flag ``visited``: the episode as
        if it had reached that state (``continuation``). From the start (heel (start_y, 0), 0
        steps, not visited) it is ``rollout``, bit for bit."""
        sp, step = self.sp, self.step_net
        step.set_scene(self._basis(scene))
        hy, hz, t, visited = float(heel[0]), float(heel[1]), int(steps), bool(visited)
        pts, acts = [(hy, hz)], []
        last = -1  # the move just made (the shield never undoes it)
        one = stack_scenes([scene], np.float32) if self.shield else None
        rows = self._shield("rows") if self.shield else None
        single = self._shield("scalar").swing(scene, one) if self._shield_first() else None
        # where a collision ends the episode: the move's clearance, the outline's extent first
        collides = transition.never
        if self.terminate_on_collision:
            ol = scene.outline
            box = (ol[:, 0].min(), ol[:, 0].max(), ol[:, 1].max())

            def collides(lay, y0, z0, y1, z1):
                return self._move_touches(box, ol, (y0, z0), (y1, z1))

        max_steps, q_values = self.max_steps, step.q_values
        choose = None if single is None else single.choose
        while True:
            if choose is not None:
                a = choose(hy, hz, q_values(hy, hz, t, 1.0 if visited else 0.0), last)
            elif self.shield:
                mask = rows.admissible(
                    np.array([hy], np.float32),
                    np.array([hz], np.float32),
                    one,
                    last_action=np.array([last]),
                )[0]
                a = self._explore(step.greedy(hy, hz, t, 1.0 if visited else 0.0, mask), mask)
            else:
                a = self._explore(step.greedy(hy, hz, t, 1.0 if visited else 0.0))
            at = (hy, hz, self.directions[a], t, visited, scene)
            out = transition.step(scalar, sp, *at, max_steps=max_steps, collides=collides)
            hy, hz, t, visited, last = out.heel_y, out.heel_z, out.time, out.visited_mid, int(a)
            pts.append((hy, hz))
            acts.append(a)
            if out.terminated or out.truncated:
                break
        return np.asarray(pts), np.asarray(acts, dtype=np.int64)

    def _shield(self, kind: str):
        """The shield's form ``kind`` (jaxexo.shield.make_shield), counting in ``shield_stats``; built
        once per generator (the forms keep no state of a swing, and the scalar one derives two
        parameter views on construction, 0.1 ms a swing)."""
        if kind not in self._shields:
            self._shields[kind] = make_shield(kind, self.np_params, self.sp, self.shield_stats)
        return self._shields[kind]

    def _shield_first(self) -> bool:
        """Whether the rollouts check the shield's moves in order of Q (greedy only; not in
        ``plain_reference``, which computes the full mask every step)."""
        return self.shield and not self._exact and self.epsilon <= 0.0

    def rollout_batch(self, scenes) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Greedy raw paths of many scenes at once (float32 NumPy, like the JAX environment). With the
        shield, a greedy rollout checks each row's best forward move first (the rows form's ``choose``);
        ``plain_reference`` computes the full mask of every row every step."""
        p = self.np_params
        lay = stack_scenes(scenes, np.float32)
        rows = self._shield("rows") if self.shield else None
        b = len(scenes)
        dirs = p.directions
        hy = lay.start_y.copy()
        hz = np.zeros(b, np.float32)
        t = np.zeros(b, np.int32)
        visited = np.zeros(b, bool)
        path = np.empty((self.max_steps + 1, b, 2), np.float32)
        acts = np.zeros((self.max_steps, b), np.int64)
        last = np.full(b, -1, np.int64)  # the move just made (the shield never undoes it)
        path[0, :, 0], path[0, :, 1] = hy, hz
        length = np.ones(b, np.int64)
        alive = np.arange(b)
        # the clearance only where a collision ends the episode
        collides = _rows_collide(p) if self.terminate_on_collision else transition.never
        for k in range(self.max_steps):
            sub = take_rows(lay, alive)
            obs = actions.observation(
                np, p, self.obs_mode, hy[alive], hz[alive], t[alive], visited[alive], sub
            )
            if self._shield_first():
                a = rows.choose(hy[alive], hz[alive], sub, self.net.q(obs), last[alive])
            else:
                mask = (
                    rows.admissible(hy[alive], hz[alive], sub, last_action=last[alive])
                    if self.shield
                    else None
                )
                a = self._explore(actions.greedy_action(np, self.net.q(obs), mask), mask)
            at = (hy[alive], hz[alive], dirs[a].T, t[alive], visited[alive], sub)
            out = transition.step(np, p, *at, max_steps=self.max_steps, collides=collides)
            hy[alive], hz[alive], t[alive] = out.heel_y, out.heel_z, out.time
            visited[alive] = out.visited_mid
            path[k + 1, alive, 0], path[k + 1, alive, 1] = out.heel_y, out.heel_z
            acts[k, alive] = a
            last[alive] = a
            length[alive] += 1
            alive = alive[~(out.terminated | out.truncated)]
            if alive.size == 0:
                break
        paths = [path[: length[i], i].astype(np.float64) for i in range(b)]
        return paths, [acts[: length[i] - 1, i] for i in range(b)]

    def fallback_generator(self):
        """CFFTG for this generator's config and clearance, built on the first fallback (its
        constants cost ~ms to derive)."""
        if self._cfftg is None:
            from jaxexo.baselines.cfftg import CFFTG  # built only when a swing falls back

            self._cfftg = CFFTG(self.config, clearance=self.clearance)
        return self._cfftg

    def _move_touches(self, box: tuple, outline: np.ndarray, prev: tuple, heel: tuple) -> bool:
        """``move_collides`` of one move on Python floats, the outline's extent ``box`` (y from, y to,
        top) given. Cheap exclusion first: a move whose feet stay above the outline's top or beside
        its extent cannot touch it (the foot is horizontal)."""
        eps = geometry.TOUCH_EPS + BOUND_SLACK
        (y0, z0), (y1, z1) = prev, heel
        if (
            min(z0, z1) > box[2] + eps
            or min(y0, y1) > box[1] + eps
            or max(y0, y1) + self.sp.foot_length < box[0] - eps
        ):
            return False
        return bool(move_collides(self.sp, np.array([prev]), np.array([heel]), outline[None])[0])

    # Trajectories ---------------------------------------------------------------------------------
    def finish(
        self,
        scenes,
        raws,
        n_points: int,
        smoothing: float,
        duration: float,
        fallback: str | None = "cfftg",
    ) -> TrajectoryBatch:
        """Checked trajectories of raw paths on their scenes: smoothed, checked and retried
        (jaxexo.swing.finish), then, with ``fallback="cfftg"``, CFFTG's plan wherever the RL
        swing still fails and CFFTG's passes (``replace_failures``)."""
        finisher = PathFinisher(self.sp, self.clearing, exact=self._exact)
        batch = finisher.finish(self.name, scenes, raws, n_points, smoothing, duration)
        if fallback is not None:
            fb = self.fallback_generator()
            batch = replace_failures(
                batch, lambda sc: fb.finish(sc, n_points, duration), fb.fallback_label
            )
        return batch

    def describe(self, traj: Trajectory) -> str:
        if traj.method == self.name:
            return f"{len(traj.raw) - 1} agent moves"
        return "polynomial path (CFFTG fallback: the RL swing was not safe)"

    def _smoothing(self, o: GenerateOptions) -> float:
        return self.smoothing if o.smoothing is None else o.smoothing

    def plan_swing(self, scene: Scene, o: GenerateOptions) -> Trajectory:
        """The greedy rollout (``rollout``) finished (``finish``) with ``o``'s options."""
        raw, _ = self.rollout(scene)
        return self.finish([scene], [raw], o.n_points, self._smoothing(o), o.duration, o.fallback)[
            0
        ]

    def plan_batch(self, scenes, o: GenerateOptions) -> TrajectoryBatch:
        """The batched greedy rollouts (``rollout_batch``) finished with ``o``'s options."""
        with blas.limited(self.batch_blas_threads):
            raws, _ = self.rollout_batch(scenes)
            return self.finish(scenes, raws, o.n_points, self._smoothing(o), o.duration, o.fallback)

    def continuation(
        self,
        scene: Scene,
        state,
        *,
        n_points: int = sm.DEFAULT_POINTS,
        smoothing: float | None = None,
        duration: float = DEFAULT_DURATION,
        fallback: str | None = "cfftg",
        swing_scene: Scene | None = None,
    ) -> Trajectory:
        """The policy's heel path from the foot's state (``continue_from``'s arguments): the greedy
        shielded rollout from the state's heel with the step count and mid-goal flag its path so
        far implies (jaxexo.swing.continuation.policy_clock), finished as ``generate`` finishes and
        checked on ``scene``; with ``fallback="cfftg"``, CFFTG's continuation from the same state
        where the policy's fails its checks and CFFTG's passes. Its heel[0] is the state's heel
        exactly. ValueError for a foot already within the margin of the new obstacle, a scene with
        other feet, or bad options (named as typed)."""
        n_points, duration = check_points(n_points), check_duration(duration)
        smoothing, fallback = check_smoothing(smoothing), check_fallback(fallback)
        check_state(state, scene, self.sp, swing_scene)
        steps, visited = policy_clock(state, scene, self.sp, self.max_steps)
        heel = (float(state.heel[0]), float(state.heel[1]))
        raw, _ = self.rollout_from(scene, heel=heel, steps=steps, visited=visited)
        s = self.smoothing if smoothing is None else smoothing
        batch = self.finish([scene], [raw], n_points, s, duration, fallback=None)
        if fallback is not None:
            fb = self.fallback_generator()

            def plan(scenes):
                return fb.continuation_batch(scenes, [state], n_points=n_points, duration=duration)

            batch = replace_failures(batch, plan, fb.fallback_label)
        return batch[0]

    def continue_from(self, scene: Scene, state, o, swing_scene) -> Trajectory:
        """``continuation`` with ``o``'s options (``replan``'s step)."""
        kw = dict(n_points=o.n_points, smoothing=o.smoothing, duration=o.duration)
        return self.continuation(scene, state, **kw, fallback=o.fallback, swing_scene=swing_scene)


def replace_failures(batch: TrajectoryBatch, planner, label: str) -> TrajectoryBatch:
    """``batch`` with each failing row replaced by the swing ``planner(scenes)`` (a TrajectoryBatch,
    one row per scene) plans for its scene where that passes, its method ``label``."""
    bad = np.flatnonzero(~batch.ok)
    if not bad.size:
        return batch
    plan = planner([batch.scenes[i] for i in bad])
    take = [j for j in range(len(bad)) if plan.ok[j]]
    notes = list(batch.notes)
    for j, i in enumerate(bad):
        rl_fail = "RL swing failed the safe-swing check: " + "; ".join(batch.reasons[i])
        notes[i] = notes[i] + (
            (rl_fail + "; CFFTG's plan is returned",)
            if j in take
            else (rl_fail, "CFFTG fallback failed too: " + "; ".join(plan.reasons[j]))
        )
    batch = dataclasses.replace(batch, notes=tuple(notes))
    if not take:
        return batch
    sub = dataclasses.replace(plan, method=label, row_methods=()).take(take)
    sub = dataclasses.replace(
        sub, notes=tuple(notes[bad[j]] + sub.notes[n] for n, j in enumerate(take))
    )
    return batch.with_rows([bad[j] for j in take], sub)


# m: how far under the touch tolerance ``move_collides``' cheap bound may fall by rounding (float32
# heels a metre from the origin round by ~1e-7 m; the margin only sends a few more moves to the
# exact test, never changes a decision).
BOUND_SLACK = 1e-4


def _rows_collide(p):
    """``transition.step``'s ``collides`` of a batch of rows: ``move_collides``."""
    return lambda lay, y0, z0, y1, z1: move_collides(
        p, np.stack([y0, z0], -1), np.stack([y1, z1], -1), lay.outline
    )


def move_collides(p, prev, heel, outline) -> np.ndarray:
    """(B,) bool: the environment's collision test (jaxexo.physics.transition.move_clearance, the
    swept clearance of the whole move) of the moves from heels ``prev`` to ``heel`` (B, 2) on
    outlines (B, K, 2), with ``p``'s foot length. The exact test runs only where a bound leaves the
    answer open: the distance of each end's foot to the outline's bounding box bounds its clearance
    from below (jaxexo.physics.swept.box_lower_bound), hence the move's
    (swept.swept_lower_bound), and a move whose bound clears the touch tolerance cannot collide."""
    ends = np.stack([prev, heel], axis=1)  # (B, 2 ends, 2)
    lb = swept.box_lower_bound(ends, p.foot_length, outline)
    d = heel - prev
    length = np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1])
    bound = swept.swept_lower_bound(np, lb[:, 0], lb[:, 1], length)
    near = (np.minimum(lb[:, 0], lb[:, 1]) <= 0.0) | (bound <= geometry.TOUCH_EPS + BOUND_SLACK)
    out = np.zeros(len(prev), bool)
    if near.any():
        c = transition.move_clearance(np, p, prev[near], heel[near], outline[near])
        out[near] = geometry.foot_collides(np, c)
    return out


def plain_reference(gen: TrajectoryGenerator) -> TrajectoryGenerator:
    """``gen`` running the plain reference implementation: the full shield mask every step and
    every move's clearance exact, each curve measured afresh. It gives the same actions, samples
    and verdicts as the fast paths; for the tests and the benchmark that compare against it, not
    part of the generator's API."""
    return gen.with_options(exact=True)


# The raw path of a long swing (m): 40 moves of 3 cm (a typical one has 25-35): the budget below holds
# for swings up to this long.
LONG_SWING_PATH = 1.2


def model_smoothing(
    shield_clearance: float, min_clearance: float, shield: bool, step_size: float = 0.03
) -> float:
    """The spline's default smoothing s (m^2, the sum of squared residuals at the agent's points,
    thesis 2.7) for a model: the thesis's 0.005 m^2 without the shield; with it, the s whose RMS
    residual over a long swing (LONG_SWING_PATH / step_size points: 40 at 3 cm) equals the shield's
    excess over the margin (env.shield_clearance - env.min_clearance: 5 mm, s = 40 x 0.005^2 = 0.001 m^2
    by default). The shielded raw path keeps that excess everywhere, so a spline that strays no further
    than it from the agent's points rarely cuts into the margin; the thesis's s (an RMS of 1.1-1.4 cm
    over 25-40 points) cuts corners by more than the excess, and its correction
    (jaxexo.swing.clearing) then lifts the whole swing (about 1 cm higher on the held-out families,
    measured). Longer steps give fewer points for the same swing, hence a smaller s."""
    if not shield:
        return sm.DEFAULT_SMOOTHING
    excess = float(shield_clearance) - float(min_clearance)
    points = LONG_SWING_PATH / float(step_size)
    return points * excess * excess if excess > 0.0 else 0.0
