"""The TD(lambda) trainer as one compiled program (thesis 2.3-2.4, 3.1-3.2).

``make_train(config)`` returns a pure ``train(key, hyper)``: one ``lax.scan`` over updates with the
environment vmapped inside; jit it, vmap it over seeds or over ``Hyperparams`` (every leaf of which
may differ: learning rate, gamma, lambda, epsilon schedule, target rate, reward weights...). Static
settings (num_envs, rollout length, layer sizes, trace view, control) come from ``TrainConfig`` and
fix the program's shapes.

One *update* = a rollout of T steps in each of N environments, then:
- forward view: lambda-returns by a reverse scan (jaxexo.train.td_lambda), then ``num_epochs`` passes
  of ``num_minibatches`` Adam steps on 0.5 (G - Q(s, a))^2 (as PQN does, with a target network);
- backward view: per-environment eligibility traces over the parameters, one Adam step per env step
  along mean_i delta_i e_i (eq 2.26).
The target network is copied every ``target_period`` updates ("hard") or moved by ``target_tau``
("polyak"). Metrics are reduced inside the scan: one row of scalars per update.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from jaxexo.config import HYPER_FIELDS, Config, TrainConfig, declared_fields, num_updates
from jaxexo.env import EnvParams, ExoStepEnv
from jaxexo.physics import dynamics, outcome
from jaxexo.train import td_lambda
from jaxexo.train.network import QNetwork


METRICS = ("episodes", "return_sum", "successes", "accurate", "env_steps", "loss", "q_mean", "epsilon")


def _hyper_from_config(cls, cfg: Config) -> "Hyperparams":
    """Each leaf of [train] (HYPER_FIELDS) at its declared dtype (float32; int32 for target_period),
    and the environment's parameters."""
    specs = dict(declared_fields(TrainConfig))
    leaves = {k: jnp.asarray(getattr(cfg.train, k), specs[k].dtype) for k in HYPER_FIELDS}
    # Budgets are compared in integers (Trainer.active): float32 counts drift past 2^24 and could stop a
    # run an update early (or late) when N T is not a power of two. budget_env_steps stays a float32
    # leaf for the epsilon schedule only; the step budget is counted in updates (clipped to int32: the
    # update counter is int32, and 2^31 updates is beyond any run).
    t = cfg.train
    leaves["budget_episodes"] = jnp.asarray(t.budget_episodes, jnp.int32)
    leaves["budget_updates"] = jnp.asarray(min(-(-t.budget_env_steps // (t.num_envs * t.rollout_steps)),
                                               2**31 - 1), jnp.int32)
    return cls(**leaves, env=EnvParams.from_config(cfg))


# Vmappable hyperparameters (pytree leaves): the fields of TrainConfig declared as leaves
# (jaxexo.config.HYPER_FIELDS; budgets: 0 means none), then the environment's parameters.
Hyperparams = struct.dataclass(type("Hyperparams", (), {
    "__annotations__": {**{k: jnp.ndarray for k in HYPER_FIELDS}, "budget_updates": jnp.ndarray, "env": EnvParams},
    "from_config": classmethod(_hyper_from_config), "__module__": __name__,
    "__doc__": "Vmappable hyperparameters (pytree leaves): HYPER_FIELDS, budget_updates (int32: the "
               "env-step budget in updates, 0: none), then env (EnvParams)."}))


@struct.dataclass
class EpisodeStats:
    ret: jnp.ndarray        # (N,) running return
    outcome: dict           # (N,) running aggregates of jaxexo.physics.outcome (clearance, limits, goal)


@struct.dataclass
class TrainState:
    params: Any
    target_params: Any
    opt_state: Any
    env_state: Any
    obs: jnp.ndarray
    stats: EpisodeStats
    traces: Any               # backward view: per-env traces; forward view: ()
    action: jnp.ndarray       # backward view: the action chosen for ``obs`` (SARSA needs it ahead)
    greedy: jnp.ndarray       # ...and whether it was greedy (Watkins cut)
    fresh: jnp.ndarray        # ``obs`` starts an episode (traces reset)
    key: jnp.ndarray
    update: jnp.ndarray       # int32: updates done (env steps done = update * N * T, Trainer.env_steps)
    episodes: jnp.ndarray     # int32: episodes finished


class Transition(NamedTuple):
    obs: jnp.ndarray
    action: jnp.ndarray
    reward: jnp.ndarray
    terminated: jnp.ndarray
    truncated: jnp.ndarray
    target_q: jnp.ndarray     # target network at the step's final observation: max_a (off-policy) or all of Q
    greedy: jnp.ndarray


class Trainer:
    """The pieces of the compiled program, for the Python driver (chunks, resume) and for sweeps."""

    def __init__(self, cfg: Config, devices=None):
        """``devices``: split the environments over these JAX devices (data parallel: each device steps
        its share of the environments and averages gradients with the others). None: one device, and
        the program stays a plain function that vmaps over seeds and hyperparameters."""
        self.cfg = cfg
        self.devices = None
        if devices is not None and len(devices) > 1:
            d = len(devices)
            while cfg.train.num_envs % d or (cfg.train.num_envs // d) % cfg.train.num_minibatches:
                d -= 1
            self.devices = list(devices)[:d] if d > 1 else None
        self.axis = "envs" if self.devices else None
        self.tc = cfg.train
        self.env = ExoStepEnv(cfg)
        self.net = QNetwork(hidden=self.tc.hidden, num_actions=self.env.num_actions,
                            layer_norm=self.tc.layer_norm)
        self.num_updates = num_updates(cfg)
        self.steps_per_update = self.tc.num_envs * self.tc.rollout_steps
        self.off_policy = self.tc.control == "off_policy"

    # --------------------------------------------------------------------------------------
    def optimizer(self, hyper: Hyperparams):
        """Adam with global-norm clipping; the learning rate decays linearly over the update budget."""
        steps = self.num_updates * (self.tc.rollout_steps if self.tc.trace == "backward"
                                    else self.tc.num_epochs * self.tc.num_minibatches)
        lr = optax.linear_schedule(hyper.lr, hyper.lr * hyper.lr_end_fraction, steps)
        return optax.chain(optax.clip_by_global_norm(hyper.max_grad_norm), optax.adam(lr))

    def env_steps(self, ts: TrainState) -> np.ndarray:
        """Env steps done, exactly (int64, on the host; any leading agent axes of ``ts`` kept): an update
        is N T steps and the state freezes once the budget is spent."""
        return np.asarray(ts.update).astype(np.int64) * self.steps_per_update

    def epsilon(self, ts: TrainState, hyper: Hyperparams):
        """Linear decay from eps_start to eps_end over eps_decay_fraction of the budget (a schedule:
        float32 is fine here, the budget itself is counted in integers, ``active``)."""
        steps = ts.update.astype(jnp.float32) * jnp.float32(self.steps_per_update)
        episodes = ts.episodes.astype(jnp.float32)
        budget_episodes = hyper.budget_episodes.astype(jnp.float32)
        frac = jnp.maximum(
            jnp.where(hyper.budget_env_steps > 0, steps / jnp.maximum(hyper.budget_env_steps, 1.0), 0.0),
            jnp.where(budget_episodes > 0, episodes / jnp.maximum(budget_episodes, 1.0), 0.0))
        w = jnp.clip(1.0 - frac / hyper.eps_decay_fraction, 0.0, 1.0)
        return hyper.eps_end + (hyper.eps_start - hyper.eps_end) * w

    def active(self, ts: TrainState, hyper: Hyperparams):
        # update * N T < budget  <=>  update < ceil(budget / (N T)): integers throughout.
        steps_left = (hyper.budget_updates <= 0) | (ts.update < hyper.budget_updates)
        eps_left = (hyper.budget_episodes <= 0) | (ts.episodes < hyper.budget_episodes)
        return steps_left & eps_left

    def init(self, key, hyper: Hyperparams) -> TrainState:
        n = self.tc.num_envs
        k_net, k_env, k_run = jax.random.split(key, 3)
        obs, env_state = jax.vmap(self.env.reset, in_axes=(0, None))(jax.random.split(k_env, n), hyper.env)
        params = self.net.init(k_net, obs[:1])
        opt_state = self.optimizer(hyper).init(params)
        backward = self.tc.trace == "backward"
        traces = jax.tree.map(lambda p: jnp.zeros((n,) + p.shape, p.dtype), params) if backward else ()
        stats = EpisodeStats(ret=jnp.zeros(n), outcome=outcome.start(jnp, (n,)))
        ts = TrainState(params=params, target_params=params, opt_state=opt_state, env_state=env_state,
                        obs=obs, stats=stats, traces=traces, action=jnp.zeros(n, jnp.int32),
                        greedy=jnp.ones(n, bool), fresh=jnp.ones(n, bool), key=k_run,
                        # Strongly typed: a weakly typed 0 would give jit a second signature after
                        # the first update (and a second compilation of the chunk program).
                        update=jnp.asarray(0, jnp.int32), episodes=jnp.asarray(0, jnp.int32))
        if backward:
            k_act, k_run = jax.random.split(k_run)
            a, g = self._act(params, obs, k_act, self.epsilon(ts, hyper), self._mask(env_state, hyper))
            ts = ts.replace(action=a, greedy=g, key=k_run)
        return ts

    # --------------------------------------------------------------------------------------
    def _psum(self, x):
        return jax.lax.psum(x, self.axis) if self.axis else x

    def _pmean(self, x):
        return jax.lax.pmean(x, self.axis) if self.axis else x

    def _local_key(self, key):
        """Per-device randomness for environments and exploration; the carried key stays shared."""
        return jax.random.fold_in(key, jax.lax.axis_index(self.axis)) if self.axis else key

    def _mask(self, env_state, hyper):
        """(N, A) admissible moves of the environments' states with the shield, else None (all)."""
        if not self.env.shield:
            return None
        # The batched mask: action_mask's decisions with the exact swept check only where needed.
        return self.env.action_masks(env_state, hyper.env)

    def _final_mask(self, mask_next, done):
        """The admissible moves of the state each step reached, for its bootstrap: ``mask_next`` (the
        next state's, which is the reached state unless the episode ended), and where it ended (auto-
        reset) the forward moves: a truncated episode's last state bootstraps on its best forward move,
        so that each step computes one mask, not two (terminated steps do not bootstrap at all)."""
        if mask_next is None:
            return None
        return jnp.where(done[:, None], jnp.asarray(dynamics.forward_moves()), mask_next)

    def _act(self, params, obs, key, eps, mask=None):
        """Epsilon-greedy (thesis 2.4.2) over the admissible moves ``mask`` (None: all): returns the
        actions and whether each is the greedy one."""
        q = self.net.apply(params, obs)
        greedy = dynamics.greedy_action(jnp, q, mask)
        ku, kr = jax.random.split(key)
        explore = jax.random.uniform(ku, greedy.shape) < eps
        if mask is None:
            rand = jax.random.randint(kr, greedy.shape, 0, self.env.num_actions)
        else:   # uniform over the admissible moves
            rand = jax.random.categorical(kr, jnp.where(mask, 0.0, -jnp.inf), axis=-1)
        a = jnp.where(explore, rand, greedy)
        return a.astype(jnp.int32), a == greedy

    def _env_step(self, key, env_state, action, hyper):
        n = action.shape[0]
        return jax.vmap(self.env.step, in_axes=(0, 0, 0, None))(
            jax.random.split(key, n), env_state, action, hyper.env)

    @staticmethod
    def _episode_stats(stats: EpisodeStats, reward, terminated, truncated, info, env_params):
        ret = stats.ret + reward
        acc = outcome.accumulate(jnp, stats.outcome, info)
        # The strict-success verdict of the episodes that ended here (jaxexo.physics.outcome, the one
        # definition), on the agent's raw moves under the behaviour policy.
        v = outcome.episode_verdict(jnp, acc, **outcome.rule(env_params))
        done = terminated | truncated
        row = jnp.stack([done.sum(), jnp.where(done, ret, 0.0).sum(), (done & v["success"]).sum(),
                         (done & v["collision_free"]).sum()])
        fresh = outcome.start(jnp, ret.shape)
        new = EpisodeStats(ret=jnp.where(done, 0.0, ret),
                           outcome=jax.tree.map(lambda f, a: jnp.where(done, f, a), fresh, acc))
        return new, row.astype(jnp.float32)

    def _bootstrap(self, q_final, next_action, done, eps):
        """Value of the state a step reached (its final observation), per the control mode."""
        if self.off_policy:
            return jnp.max(q_final, axis=-1)                               # eq 2.28
        q_next = jnp.take_along_axis(q_final, next_action[..., None], axis=-1)[..., 0]
        return jnp.where(done, td_lambda.epsilon_greedy_value(q_final, eps), q_next)  # eq 2.27

    def _finish_update(self, ts: TrainState, new: TrainState, hyper, row_ep, loss, q_mean, eps):
        upd = new.update + 1
        if self.tc.target == "hard":
            copy = (upd % hyper.target_period) == 0
            target = jax.tree.map(lambda p, t: jnp.where(copy, p, t), new.params, new.target_params)
        else:
            target = optax.incremental_update(new.params, new.target_params, hyper.target_tau)
        steps = float(self.tc.num_envs * self.tc.rollout_steps)
        # row_ep[0] counts this update's finished episodes (<= N): exact in float32, added as an integer.
        new = new.replace(target_params=target, update=upd, episodes=new.episodes + row_ep[0].astype(jnp.int32))
        # Past the budget the state is frozen (vmapped seeds and sweeps reach it at different times).
        act = self.active(ts, hyper)
        new = jax.tree.map(lambda a, b: jnp.where(act, a, b), new, ts)
        metrics = jnp.concatenate([row_ep, jnp.stack([steps, loss, q_mean, eps])]) * act
        return new, metrics

    # --------------------------------------------------------------------------------------
    def _update_forward(self, ts: TrainState, hyper: Hyperparams):
        eps = self.epsilon(ts, hyper)

        def step(carry, _):
            env_state, obs, mask, stats, key = carry
            key, kl = jax.random.split(key)
            ka, ke = jax.random.split(self._local_key(kl))
            a, greedy = self._act(ts.params, obs, ka, eps, mask)
            obs2, env_state, r, term, trunc, info = self._env_step(ke, env_state, a, hyper)
            stats, row = self._episode_stats(stats, r, term, trunc, info, hyper.env)
            mask2 = self._mask(env_state, hyper)
            # The bootstrap's target-network pass runs here, on this step's N observations, rather than
            # on all T x N after the rollout: the same arithmetic on a working set that stays in cache.
            q_final = td_lambda.restrict(self.net.apply(ts.target_params, info["final_observation"]),
                                         self._final_mask(mask2, term | trunc))     # (N, A)
            target_q = jnp.max(q_final, axis=-1) if self.off_policy else q_final
            return (env_state, obs2, mask2, stats, key), (Transition(obs, a, r, term, trunc, target_q, greedy), row)

        (env_state, obs, _, stats, key), (tr, rows) = jax.lax.scan(
            step, (ts.env_state, ts.obs, self._mask(ts.env_state, hyper), ts.stats, ts.key), None,
            length=self.tc.rollout_steps)
        done = tr.terminated | tr.truncated
        if self.off_policy:
            boot = tr.target_q                                                        # eq 2.28
        else:
            next_action = jnp.concatenate([tr.action[1:], tr.action[-1:]], axis=0)
            last = jnp.arange(self.tc.rollout_steps)[:, None] == self.tc.rollout_steps - 1
            boot = self._bootstrap(tr.target_q, next_action, done | last, eps)        # eq 2.27
        cont = tr.greedy if self.off_policy else jnp.ones_like(tr.greedy)
        returns = td_lambda.lambda_returns(tr.reward, boot, tr.terminated, done, cont, hyper.gamma, hyper.lam)

        tx = self.optimizer(hyper)
        n_mb = self.tc.num_minibatches
        data = (tr.obs, tr.action, returns)  # (T, N, ...)

        def loss_fn(params, obs, action, target):
            q = self.net.apply(params, obs)
            qa = jnp.take_along_axis(q, action[..., None], axis=-1)[..., 0]
            return 0.5 * jnp.mean((target - qa) ** 2), jnp.mean(qa)

        def epoch(carry, key):
            params, opt_state = carry
            # Minibatches are blocks of environments (all T steps of each), shuffled by a permutation
            # of the N environments: as random as a permutation of the T x N samples for i.i.d.
            # environments, and far cheaper (no sort of T x N keys).
            if n_mb == 1:   # one minibatch of every sample: its order does not matter
                mb = jax.tree.map(lambda x: x[None], data)
            else:
                perm = jax.random.permutation(key, tr.obs.shape[1])
                mb = jax.tree.map(
                    lambda x: jnp.swapaxes(x[:, perm].reshape((x.shape[0], n_mb, -1) + x.shape[2:]), 0, 1), data)

            def minibatch(carry, m):
                params, opt_state = carry
                (loss, qm), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, *m)
                grads, loss, qm = self._pmean((grads, loss, qm))  # data parallel: average over devices
                updates, opt_state = tx.update(grads, opt_state, params)
                return (optax.apply_updates(params, updates), opt_state), (loss, qm)

            return jax.lax.scan(minibatch, (params, opt_state), mb)

        key, kp = jax.random.split(key)
        kp = self._local_key(kp)
        (params, opt_state), (losses, qms) = jax.lax.scan(
            epoch, (ts.params, ts.opt_state), jax.random.split(kp, self.tc.num_epochs))
        new = ts.replace(params=params, opt_state=opt_state, env_state=env_state, obs=obs, stats=stats, key=key)
        return self._finish_update(ts, new, hyper, self._psum(rows.sum(0)), losses.mean(), qms.mean(), eps)

    def _update_backward(self, ts: TrainState, hyper: Hyperparams):
        eps = self.epsilon(ts, hyper)
        tx = self.optimizer(hyper)

        def q_sa(params, obs, action):
            return self.net.apply(params, obs[None])[0, action]

        grad_q = jax.vmap(jax.value_and_grad(q_sa), in_axes=(None, 0, 0))

        def step(carry, _):
            params, opt_state, traces, env_state, obs, a, greedy, fresh, stats, key = carry
            key, kl = jax.random.split(key)
            ka, ke = jax.random.split(self._local_key(kl))
            qsa, grads = grad_q(params, obs, a)
            # Eq 2.22: decay by gamma * lambda, reset at episode start, cut after exploration (Watkins).
            keep = ~fresh & (greedy if self.off_policy else True)
            traces = td_lambda.add_gradient(
                td_lambda.decay_traces(traces, hyper.gamma, hyper.lam, keep), grads, self.tc.trace_kind)
            obs2, env_state, r, term, trunc, info = self._env_step(ke, env_state, a, hyper)
            stats, row = self._episode_stats(stats, r, term, trunc, info, hyper.env)
            done = term | trunc
            mask2 = self._mask(env_state, hyper)
            a2, greedy2 = self._act(params, obs2, ka, eps, mask2)
            q_final = td_lambda.restrict(self.net.apply(ts.target_params, info["final_observation"]),
                                         self._final_mask(mask2, done))
            boot = self._bootstrap(q_final, a2, done, eps)
            delta = r + hyper.gamma * (1.0 - term) * boot - qsa                     # eq 2.26
            direction = self._pmean(td_lambda.trace_update_direction(traces, delta))
            # Adam minimises: feed it the negative ascent direction of eq 2.26.
            updates, opt_state = tx.update(jax.tree.map(jnp.negative, direction), opt_state, params)
            params = optax.apply_updates(params, updates)
            carry = (params, opt_state, traces, env_state, obs2, a2, greedy2, done, stats, key)
            return carry, (row, self._pmean(0.5 * jnp.mean(delta ** 2)), self._pmean(jnp.mean(qsa)))

        init = (ts.params, ts.opt_state, ts.traces, ts.env_state, ts.obs, ts.action, ts.greedy, ts.fresh,
                ts.stats, ts.key)
        (params, opt_state, traces, env_state, obs, a, greedy, fresh, stats, key), (rows, losses, qms) = \
            jax.lax.scan(step, init, None, length=self.tc.rollout_steps)
        new = ts.replace(params=params, opt_state=opt_state, traces=traces, env_state=env_state, obs=obs,
                         action=a, greedy=greedy, fresh=fresh, stats=stats, key=key)
        return self._finish_update(ts, new, hyper, self._psum(rows.sum(0)), losses.mean(), qms.mean(), eps)

    def update(self, ts: TrainState, hyper: Hyperparams):
        if self.tc.trace == "forward":
            return self._update_forward(ts, hyper)
        return self._update_backward(ts, hyper)

    def _mesh_specs(self):
        """The device mesh and the TrainState of PartitionSpecs the data-parallel program uses: the
        per-environment fields split over the ``envs`` axis, the rest (parameters, optimizer, key,
        counters) replicated."""
        from jax.sharding import Mesh, PartitionSpec as P

        mesh = Mesh(np.array(self.devices), (self.axis,))
        per_env = {"env_state", "obs", "stats", "traces", "action", "greedy", "fresh"}
        spec = TrainState(**{f.name: (P(self.axis) if f.name in per_env else P())
                             for f in dataclasses.fields(TrainState)})
        return mesh, spec

    def place(self, ts: TrainState) -> TrainState:
        """``ts`` laid out as ``run`` returns it (a no-op on one device). ``jit(run)`` keys its compiled
        programs on the inputs' shardings: a state fresh from ``init`` (one device) or from a
        checkpoint (host arrays) has another layout than the state a chunk returns (split over the
        mesh), so without this the second chunk compiles the whole program again. Placing the state
        first gives every call one signature: one compilation per run (tests/test_compile_once.py counts
        them). Only where the data lives changes, never a value."""
        if not self.axis:
            return ts
        from jax.sharding import NamedSharding

        mesh, spec = self._mesh_specs()
        shardings = jax.tree.map(lambda p: NamedSharding(mesh, p), spec,
                                 is_leaf=lambda x: isinstance(x, jax.sharding.PartitionSpec))
        return jax.device_put(ts, shardings)

    def run(self, ts: TrainState, hyper: Hyperparams, n_updates: int):
        """``n_updates`` updates in one scan; returns the state and a (n_updates, len(METRICS)) array.
        With several devices, pass ``place(ts)`` on the first call (one compilation, see ``place``)."""
        def scan(ts, hyper):
            return jax.lax.scan(lambda s, _: self.update(s, hyper), ts, None, length=n_updates)

        if not self.axis:
            return scan(ts, hyper)
        from jax.sharding import PartitionSpec as P

        mesh, spec = self._mesh_specs()
        fn = jax.shard_map(scan, mesh=mesh, in_specs=(spec, P()), out_specs=(spec, P()), check_vma=False)
        return fn(ts, hyper)


def make_train(cfg: Config):
    """A pure ``train(key, hyper) -> (TrainState, metrics)`` running the whole budget in one scan.

    jit it; vmap it over keys (seeds) and/or Hyperparams (configurations of equal static settings)."""
    trainer = Trainer(cfg)

    def train(key, hyper: Hyperparams):
        return trainer.run(trainer.init(key, hyper), hyper, trainer.num_updates)

    return train
