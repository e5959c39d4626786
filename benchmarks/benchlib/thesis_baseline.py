"""The thesis's way of training (one environment in a Python loop, one PyTorch update per step from a
replay batch of 32, truncated lambda-returns done right), the baseline jaxexo's trainer is measured
against. Needs the ``bench`` extra; nothing in jaxexo proper imports it. Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

BATCH_SIZE = 32  # thesis 2.4.3 (the batch the notebook samples)


# --------------------------------------------------------------------------------------------
# Replay buffer and lambda-returns (NumPy; no torch needed)
# --------------------------------------------------------------------------------------------


class ReplayBuffer:
    """A ring buffer of transitions kept in the order they happened, so that a sampled transition's
    successors in its episode can be read back for its lambda-return.

    Per slot: obs, action, reward, terminated (the goal ended the episode: no bootstrap), done
    (terminated or truncated: the episode's last step), next_obs (the observation the step reached,
    before any reset)."""

    def __init__(self, capacity: int, obs_dim: int):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.obs = np.zeros((capacity, obs_dim), np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), np.float32)
        self.action = np.zeros(capacity, np.int64)
        self.reward = np.zeros(capacity, np.float32)
        self.terminated = np.zeros(capacity, bool)
        self.done = np.zeros(capacity, bool)
        self.size = 0
        self.head = 0  # next slot to write

    def add(self, obs, action, reward, terminated, done, next_obs) -> None:
        i = self.head
        self.obs[i] = obs
        self.action[i] = action
        self.reward[i] = reward
        self.terminated[i] = terminated
        self.done[i] = done
        self.next_obs[i] = next_obs
        self.head = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int) -> np.ndarray:
        """Uniform random slots (with replacement)."""
        return rng.integers(0, self.size, size=batch)

    def windows(self, idx: np.ndarray, horizon: int) -> tuple[np.ndarray, np.ndarray]:
        """Slots (B, H) of each sampled transition and its next H - 1 successors, and a mask (B, H)
        of those that exist: same episode (no ``done`` before them) and already written."""
        k = np.arange(horizon)
        slots = (idx[:, None] + k[None, :]) % self.capacity
        newest = (self.head - 1) % self.capacity
        ahead = (newest - idx) % self.capacity  # successors written after idx
        valid = k[None, :] <= ahead[:, None]
        ended = np.cumsum(self.done[slots], axis=1)  # episode ended at or before step k
        valid[:, 1:] &= ended[:, :-1] == 0
        return slots, valid


def truncated_lambda_returns(reward, boot, terminated, valid, cont, gamma: float, lam: float):
    """Lambda-returns (eq 2.19, recursive form) of windows of transitions, batch-major (B, H).

    ``boot[:, k]``: value of the state step k reached; ``terminated[:, k]``: no bootstrap;
    ``valid[:, k]``: step k belongs to the window (a prefix of each row); ``cont[:, k]``: the chain
    may continue from step k - 1 into step k (Watkins: the action at k is the greedy one).
    G_k = r_k + gamma (1 - term_k) [(1 - l_k) boot_k + l_k G_{k+1}], l_k = lam cont_{k+1} valid_{k+1}
    and at a window's last valid step G = r + gamma (1 - term) boot. Returns G[:, 0]."""
    B, H = reward.shape
    g = np.zeros(B, np.float64)
    for k in range(H - 1, -1, -1):
        if k + 1 < H:
            lk = lam * cont[:, k + 1] * valid[:, k + 1]
        else:
            lk = np.zeros(B)
        gk = reward[:, k] + gamma * (1.0 - terminated[:, k]) * ((1.0 - lk) * boot[:, k] + lk * g)
        g = np.where(valid[:, k], gk, g)
    return g


# --------------------------------------------------------------------------------------------
# The environment in NumPy, one episode at a time (the thesis's environment was plain Python)
# --------------------------------------------------------------------------------------------


class NumpyExoEnv:
    """ExoStepEnv's rules stepped one environment at a time in NumPy (float32, like the JAX env):
    the same move, transition, reward and observation functions (``jaxexo.physics.transition``, ``jaxexo.physics.actions``).

    Layouts come from a pool drawn once by the one scenario generator (``layout_pool``), in
    a fresh random order on every pass, so both trainers see the same layout distribution and no
    sampling rule is written twice. ``reset() -> obs``; ``step(a) -> (obs, reward, terminated,
    truncated, info)`` with ``info["success"]`` the strict success of a finished episode."""

    def __init__(self, cfg, pool, seed: int = 0):
        from jaxexo.config import numpy_params
        from jaxexo.physics import actions, outcome, transition

        self.actions, self.transition, self.dyn_outcome = actions, transition, outcome
        self.p = numpy_params(cfg)
        self.obs_mode = cfg.env.obs_mode
        self.max_steps = int(cfg.env.max_steps)
        # a physics Scene [N]
        self.pool = pool._replace(
            **{k: np.asarray(v) for k, v in pool._asdict().items() if v is not None}
        )
        self.n_layouts = len(self.pool.start_y)
        self.rng = np.random.default_rng(seed)
        self.order = self.rng.permutation(self.n_layouts)
        self.next = 0

    def _layout(self, i: int):
        return self.pool._replace(
            **{k: v[i] for k, v in self.pool._asdict().items() if v is not None}
        )

    def _obs(self):
        return self.actions.observation(
            np, self.p, self.obs_mode, self.heel[0], self.heel[1], self.time, self.visited, self.lay
        )

    def reset(self) -> np.ndarray:
        if self.next == self.n_layouts:
            self.order, self.next = self.rng.permutation(self.n_layouts), 0
        self.lay = self._layout(self.order[self.next])
        self.next += 1
        self.heel = np.stack([self.lay.start_y, np.float32(0.0)])
        self.time = np.int32(0)
        self.visited = np.bool_(False)
        self.outcome = self.dyn_outcome.start(np)
        self.max_y = self.heel[0]
        self.last = -1  # the move just made (rewards.turn_of)
        return self._obs()

    def step(self, action: int):
        p = self.p
        at = (*self.heel, p.directions[action], self.time, self.visited, self.lay)
        out = self.transition.step(
            np,
            p,
            *at,
            max_steps=self.max_steps,
            max_y=self.max_y,
            action=action,
            last_action=self.last,
        )
        self.heel, self.time, self.last = out.info.heel, out.time, action
        self.visited, self.max_y = out.visited_mid, out.max_y
        self.outcome = self.dyn_outcome.accumulate(np, self.outcome, out.info)
        terminated = bool(out.terminated)
        truncated = (not terminated) and bool(out.truncated)  # gym's: not both
        # The one strict-success verdict (jaxexo.physics.outcome), as the JAX trainer counts it.
        info = out.info._asdict()
        info["success"] = (terminated or truncated) and bool(
            self.dyn_outcome.episode_verdict(np, self.outcome, **self.dyn_outcome.rule(p)).success
        )
        return self._obs(), float(out.reward), terminated, truncated, info


def layout_pool(cfg, n: int, seed: int = 0):
    """n layouts of the config's distribution (jaxexo.physics.scenarios, the scenes the JAX
    environment's reset draws for the key words (seed, i)), as NumPy arrays."""
    from jaxexo.config import numpy_params
    from jaxexo.physics import scenarios

    return scenarios.scenario_layouts(np, numpy_params(cfg), seed, n)


# --------------------------------------------------------------------------------------------
# The PyTorch learner
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BaselineSettings:
    """The sequential learner's settings. Those the thesis does not give (replay size, target
    period, warm-up) are the common DQN choices; the rest follow the jaxexo config it trains."""

    batch_size: int = BATCH_SIZE
    horizon: int = 8  # lambda-return window (jaxexo's rollout_steps plays this role)
    replay_capacity: int = 100_000
    learning_starts: int = BATCH_SIZE
    target_period: int = 500  # env steps (= updates) between copies of Q_main into Q_target
    torch_threads: int = 1
    seed: int = 0


def build_torch_network(obs_dim: int, hidden, num_actions: int, layer_norm: bool):
    """The Q-network in PyTorch: Linear -> (LayerNorm) -> ReLU per hidden layer, then Linear
    (thesis Fig. 2.2 for hidden = 64, 32, 32, 32); the same layout as jaxexo.train.network."""
    import torch

    layers, d = [], obs_dim
    for h in hidden:
        layers.append(torch.nn.Linear(d, h))
        if layer_norm:
            from jaxexo.storage.policy_file import LAYER_NORM_EPS

            layers.append(torch.nn.LayerNorm(h, eps=LAYER_NORM_EPS))
        layers.append(torch.nn.ReLU())
        d = h
    layers.append(torch.nn.Linear(d, num_actions))
    return torch.nn.Sequential(*layers)


class SequentialTDLambda:
    """Thesis-style TD(lambda): one environment, one Adam step per environment step on a replay
    batch, targets from Q_target. ``env`` has ``reset() -> obs`` and ``step(action) -> (obs,
    reward, terminated, truncated, info)`` (``obs`` of the step is the reached observation; the
    caller resets after a finished episode)."""

    def __init__(
        self,
        env,
        obs_dim: int,
        num_actions: int,
        hidden,
        layer_norm: bool,
        *,
        lr: float,
        gamma: float,
        lam: float,
        eps_start: float,
        eps_end: float,
        eps_decay_steps: int,
        max_grad_norm: float,
        off_policy: bool = True,
        settings: BaselineSettings = BaselineSettings(),
    ):
        import torch

        self.torch = torch
        torch.set_num_threads(settings.torch_threads)
        torch.manual_seed(settings.seed)
        self.env = env
        self.s = settings
        self.num_actions = num_actions
        self.gamma, self.lam = float(gamma), float(lam)
        self.eps_start, self.eps_end, self.eps_decay_steps = (
            float(eps_start),
            float(eps_end),
            int(eps_decay_steps),
        )
        self.max_grad_norm = float(max_grad_norm)
        self.off_policy = off_policy
        self.q = build_torch_network(obs_dim, hidden, num_actions, layer_norm)
        self.q_target = build_torch_network(obs_dim, hidden, num_actions, layer_norm)
        self.q_target.load_state_dict(self.q.state_dict())
        self.q_target.requires_grad_(False)
        self.opt = torch.optim.Adam(self.q.parameters(), lr=lr, foreach=True)
        self.buffer = ReplayBuffer(settings.replay_capacity, obs_dim)
        self.rng = np.random.default_rng(settings.seed)
        self.env_steps = 0
        self.updates = 0
        self.episodes = 0
        self.successes = 0
        self.obs = np.asarray(env.reset(), np.float32)

    def epsilon(self) -> float:
        """Linear decay over ``eps_decay_steps`` env steps (jaxexo's schedule, in env steps)."""
        w = max(0.0, 1.0 - self.env_steps / max(self.eps_decay_steps, 1))
        return self.eps_end + (self.eps_start - self.eps_end) * w

    def act(self, obs: np.ndarray) -> int:
        if self.rng.random() < self.epsilon():
            return int(self.rng.integers(self.num_actions))
        with self.torch.inference_mode():
            q = self.q(self.torch.from_numpy(obs)[None])
        return int(q.argmax())

    def targets(self, idx: np.ndarray) -> np.ndarray:
        """Truncated lambda-returns of the sampled transitions (see the module docstring)."""
        torch, b = self.torch, self.buffer
        slots, valid = b.windows(idx, self.s.horizon)
        B, H = slots.shape
        with torch.inference_mode():
            q_next = (
                self.q_target(torch.from_numpy(b.next_obs[slots.reshape(-1)]))
                .numpy()
                .reshape(B, H, -1)
            )
        act = b.action[slots]
        if self.off_policy:
            boot = q_next.max(-1)  # eq 2.28
            # Watkins: continue into step k only if its stored action is greedy at its state.
            greedy_next = q_next.argmax(-1)  # at the state step k reached
            cont = np.ones((B, H), bool)
            cont[:, 1:] = act[:, 1:] == greedy_next[:, :-1]
        else:
            # SARSA (eq 2.27): the next stored action; at a window's end, the greedy value.
            nxt = np.concatenate([act[:, 1:], act[:, -1:]], axis=1)
            boot = np.take_along_axis(q_next, nxt[..., None], -1)[..., 0]
            last = np.zeros((B, H), bool)
            last[:, :-1] = ~valid[:, 1:]
            last[:, -1] = True
            last |= b.done[slots]
            boot = np.where(last, q_next.max(-1), boot)
            cont = np.ones((B, H), bool)
        return truncated_lambda_returns(
            b.reward[slots], boot, b.terminated[slots], valid, cont, self.gamma, self.lam
        )

    def update(self) -> float:
        torch, b = self.torch, self.buffer
        idx = b.sample(self.rng, self.s.batch_size)
        g = torch.from_numpy(self.targets(idx).astype(np.float32))
        q = self.q(torch.from_numpy(b.obs[idx]))
        qa = q.gather(1, torch.from_numpy(b.action[idx])[:, None])[:, 0]
        loss = 0.5 * ((g - qa) ** 2).mean()
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.q.parameters(), self.max_grad_norm, foreach=True)
        self.opt.step()
        self.updates += 1
        if self.updates % self.s.target_period == 0:
            self.q_target.load_state_dict(self.q.state_dict())
        return float(loss.detach())

    def step(self) -> None:
        """One environment step and (after the warm-up) one update."""
        a = self.act(self.obs)
        obs2, r, term, trunc, info = self.env.step(a)
        obs2 = np.asarray(obs2, np.float32)
        done = bool(term or trunc)
        self.buffer.add(self.obs, a, r, term, done, obs2)
        self.env_steps += 1
        if done:
            self.episodes += 1
            self.successes += bool(info.get("success", False))
            self.obs = np.asarray(self.env.reset(), np.float32)
        else:
            self.obs = obs2
        if self.buffer.size >= max(self.s.learning_starts, self.s.batch_size):
            self.update()

    def train(
        self,
        *,
        seconds: float = math.inf,
        env_steps: int | None = None,
        callback=None,
        callback_every: int = 0,
    ) -> dict:
        """Step until the time or step budget is spent. ``callback(self, train_seconds)`` runs every
        ``callback_every`` env steps, off the clock; returning True stops training."""
        train_s = 0.0
        stop = False
        while not stop:
            n = callback_every or 1000
            if env_steps is not None:
                n = min(n, env_steps - self.env_steps)
            if n <= 0 or train_s >= seconds:
                break
            t0 = time.perf_counter()
            for _ in range(n):
                self.step()
                if train_s + (time.perf_counter() - t0) >= seconds:
                    break
            train_s += time.perf_counter() - t0
            if callback is not None and callback_every:
                stop = bool(callback(self, train_s))
        return {
            "env_steps": self.env_steps,
            "updates": self.updates,
            "episodes": self.episodes,
            "train_seconds": train_s,
            "env_steps_per_s": self.env_steps / max(train_s, 1e-9),
        }

    def export_flax_params(self) -> dict:
        """The main network's weights in flax's layout (jaxexo.train.network.QNetwork), so that
        jaxexo's own validator scores the baseline on the same layouts as jaxexo's trainer."""
        lin = [m for m in self.q if isinstance(m, self.torch.nn.Linear)]
        norms = [m for m in self.q if isinstance(m, self.torch.nn.LayerNorm)]
        p = {}
        for i, m in enumerate(lin):
            name = "out" if i == len(lin) - 1 else f"dense_{i}"
            p[name] = {
                "kernel": m.weight.detach().numpy().T.copy(),
                "bias": m.bias.detach().numpy().copy(),
            }
        for i, m in enumerate(norms):
            p[f"norm_{i}"] = {
                "scale": m.weight.detach().numpy().copy(),
                "bias": m.bias.detach().numpy().copy(),
            }
        return {"params": p}
