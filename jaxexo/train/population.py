"""``[train] population = K``: K agents of one config (seeds seed .. seed + K - 1) trained as one
compiled program, every member scored on the same validation scenes after each chunk; each member's
best chunk is a candidate, and the candidate a wearer would choose is exported (jaxexo.train.selection:
the most safe swings, then the timed swing and lift against CFFTG's, as the NumPy generator gives them).

Why: whether a heel-only thesis learner learns depends on its seed (benchmarks/results/thesis-seeds_*);
a practitioner trains several and keeps the best on validation. Seeds vmap, so a population costs
far less wall time than K runs one after the other (benchmarks/results/population_*).

The program: ``jit(shard_map(lax.map(vmap(member))))`` (jaxexo.train.lanes.over_lanes), where
``member`` runs one chunk of the trainer's scan and scores the greedy policy on the validation
layouts (drawn from the training distribution: jaxexo.train.evaluate.validation_set; never the test
or held-out obstacles). The members are split over the CPU devices and run in fixed blocks of
``LANES``, so a member's arithmetic is the same whether it trains alone, with 3 or 15 others, or in a
sweep chunk (the group-size independence of jaxexo.train.lanes; tests/test_population.py), and on
any number of devices from two up (``population_devices``; a process with one CPU device compiles an
unpartitioned program, whose members agree with each other but not with a partitioned one's).

The run directory is the one-agent driver's (jaxexo.train.driver), with per-member content:
- metrics.jsonl: one line per chunk: ``members``, each member's row (the one-agent row plus its
  ``seed``, ``validation_success_raw`` and ``diverged``), and ``best_member`` so far;
- policy.npz: the exported member's best chunk; members/seed_<seed>.npz: every candidate's;
- eval.json: the exported member's test figures (as for one agent, ``seed`` its seed), ``population``,
  ``base_seed``, ``exported_member``, and ``members``: per member its ``seed``, ``validation_curve``
  (validation_success_raw after each chunk, null after it diverged), ``selected_chunk``,
  ``validation_success_raw`` at that chunk, ``diverged_chunk`` (or null) and its test figures;
  ``selection``: each candidate's wearer score (jaxexo.train.selection.WearerScore; empty when only
  one candidate remained) and ``selection_seconds``;
- checkpoint.msgpack: every member's state and best parameters, and the per-member bookkeeping.

Resume, the directory lock, checksums and the config checks are the one-agent driver's. A member whose
loss or parameters become non-finite is dropped from the choice (``diverged_chunk``), not the run; if
every member diverges, training stops and TrainingDiverged is raised as for one agent.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from flax import serialization

from jaxexo.config import Config, ConfigError
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.atomic import append_line, atomic_write, write_figure
from jaxexo.storage.checkpoint import CheckpointError, pack_checkpoint
from jaxexo.storage.rundir import TrainingDiverged
from jaxexo.train.lanes import LANES, over_lanes, padded_agents
from jaxexo.train import run_files as F
from jaxexo.train.evaluate import make_evaluator, make_rollouts, validation_set
from jaxexo.train.trainer import Hyperparams, Trainer


def _finite(tree) -> jnp.ndarray:
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(tree)]))


def population_devices(n_members: int, devices) -> list:
    """The devices a population uses: as many as it fills with whole blocks of LANES members, but at
    least two where there are two. XLA compiles a program over one device without partitioning and
    over several with it, and the two differ in the last bits (measured: a member's bytes are equal
    on 2 and 4 devices, not on 1 and 2), so a population never drops to one device because it is
    small: its members then train as they do in a larger population or a sweep on the same machine."""
    devices = list(devices)
    return devices[:min(len(devices), max(2, -(-n_members // LANES)))]


class Population:
    """The compiled programs of a population of one config: ``init(seeds)`` and ``chunk(state)``.

    The state has a leading member axis padded to ``padded`` (copies of the first member, whose
    results are dropped); ``real(x)`` cuts any output back to the real members."""

    def __init__(self, cfg: Config, seeds, devices=None, n_chunk: int | None = None):
        self.cfg, self.seeds = cfg, [int(s) for s in seeds]
        if not self.seeds:
            raise ConfigError("train.population: a population needs at least one member")
        self.trainer = Trainer(cfg)     # one device per member: no data parallelism inside a member
        self.devices = population_devices(len(self.seeds), devices if devices is not None else jax.local_devices())
        self.padded = padded_agents(len(self.seeds), len(self.devices))
        self.n_chunk = n_chunk if n_chunk is not None else F.chunking(cfg, self.trainer)[0]
        hyper = Hyperparams.from_config(cfg)
        self.hyper = jax.tree.map(lambda x: np.stack([np.asarray(x)] * self.padded), hyper)
        env, self.val_params, self.val_layouts = validation_set(cfg)
        rollout = make_rollouts(env, self.trainer.net.apply, cfg.env.max_steps)
        trainer, n_chunk_ = self.trainer, self.n_chunk

        def member(ts, hyper, layouts, vparams):
            ts, m = trainer.run(ts, hyper, n_chunk_)
            score = jnp.mean(rollout(ts.params, layouts, vparams)["success"].astype(jnp.float32))
            finite = _finite(ts.params) & _finite(ts.target_params) & jnp.all(jnp.isfinite(m))
            return ts, m, score, finite

        self._init = over_lanes(trainer.init, self.devices, n_args=2)
        self._chunk = over_lanes(member, self.devices, n_args=2, shared=2)
        self._active = jax.jit(jax.vmap(trainer.active))

    @property
    def size(self) -> int:
        return len(self.seeds)

    def pad(self, tree):
        """Members -> the padded batch (copies of the first member after the real ones)."""
        extra = self.padded - self.size
        return jax.tree.map(lambda x: np.concatenate([np.asarray(x)] + [np.asarray(x)[:1]] * extra), tree)

    def real(self, tree):
        return jax.tree.map(lambda x: np.asarray(x)[:self.size], tree)

    def init(self):
        keys = np.stack([np.asarray(jax.random.PRNGKey(s)) for s in self.seeds])
        return self._init(self.pad(keys), self.hyper)

    def chunk(self, ts):
        """One chunk for every member: (state, metrics (padded, n_chunk, len(METRICS)), validation
        success (padded,), finite (padded,))."""
        return self._chunk(ts, self.hyper, self.val_layouts, self.val_params)

    def active(self, ts) -> np.ndarray:
        return np.asarray(self._active(ts, self.hyper))[:self.size]


class _Counters:
    """The two counters ``run_files.chunk_row`` reads from a state, for one member."""

    def __init__(self, update, episodes):
        self.update, self.episodes = update, episodes


def plot_population_curve(path: Path, rows: list[dict], exported: int | None) -> None:
    """Every member's training success and validation success against its episodes; the exported
    member drawn bold."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    for i in range(len(rows[0]["members"])):
        mem = [r["members"][i] for r in rows]
        ep = [m["episodes"] for m in mem]
        bold = dict(lw=2.2, zorder=3) if i == exported else dict(lw=0.9, alpha=0.6)
        label = f"seed {mem[0]['seed']}" + (" (exported)" if i == exported else "")
        a1.plot(ep, [m["success_raw_rate"] for m in mem], label=label, **bold)
        a2.plot(ep, [np.nan if m["validation_success_raw"] is None else m["validation_success_raw"] for m in mem],
                label=label, **bold)
    a1.set_ylabel("training strict success\n(behaviour policy)")
    a1.set_title(f"Population of {len(rows[0]['members'])}: training and validation per member")
    a2.set_ylabel("validation strict success\n(greedy, training layouts)")
    a2.set_xlabel("episodes")
    for a in (a1, a2):
        a.set_ylim(-0.02, 1.02)
        a.grid(alpha=0.3)
    a2.legend(loc="lower right", fontsize=7, ncol=2)
    fig.tight_layout()
    write_figure(path, fig, dpi=110)
    plt.close(fig)


def choose(best_score: np.ndarray, best_chunk: np.ndarray, diverged: np.ndarray) -> int | None:
    """The member to export: the highest best validation score among the members that never diverged
    and finished a chunk (the lowest seed on a tie); None if there is none."""
    ok = [i for i in range(len(best_score)) if diverged[i] == 0 and best_chunk[i] > 0]
    if not ok:
        return None
    return max(ok, key=lambda i: (best_score[i], -i))


def run_population(cfg: Config, out: Path, seed: int, resume: bool, progress: bool, eval_episodes) -> dict:
    """The population driver, called by ``driver.run_training`` (which holds the directory's lock)."""
    from jaxexo.config.memory import check_memory

    check_memory(cfg)
    K = cfg.train.population
    ckpt, book_path, metrics_path = out / F.CHECKPOINT, out / F.BOOKKEEPING, out / "metrics.jsonl"
    raw = F.prepare_dir(out, cfg, seed, resume)
    t_start = time.perf_counter()
    pop = Population(cfg, range(seed, seed + K))
    n_chunk, total_chunks = F.chunking(cfg, pop.trainer)
    ts = pop.init()
    start = pop.real(ts)
    best_params = pop.real(ts.params)
    best_score = np.full(K, -1.0)
    best_chunk = np.zeros(K, np.int64)
    diverged = np.zeros(K, np.int64)         # the chunk a member diverged in, 0: never
    rows: list[dict] = []
    chunks_done, wall_before = 0, 0.0
    if resume and raw is None:
        atomic_write(metrics_path, "")
    if raw is not None:
        if "members" not in raw:
            raise CheckpointError(f"{ckpt}: a one-agent checkpoint; this config trains a population of {K}")
        if (raw["book"]["devices"] == 1) != (len(pop.devices) == 1):
            # One device compiles an unpartitioned program, several a partitioned one: their arithmetic
            # differs in the last bits (population_devices), so the rest of the run would not be this run's.
            need = "one CPU device" if raw["book"]["devices"] == 1 else "two or more CPU devices"
            raise ConfigError(f"--resume: the population ran on {raw['book']['devices']} device(s), this process "
                              f"gives it {len(pop.devices)}; resume it with {need}")
        for name, template in (("state", serialization.to_state_dict(start)),
                               ("best_params", serialization.to_state_dict(best_params))):
            bad = F.tree_mismatch(template, raw[name])
            if bad:
                raise CheckpointError(f"{ckpt}: does not fit this config's population state ({name}{bad})")
        members = raw["members"]
        for k in ("best_score", "best_chunk", "diverged"):
            if not isinstance(members, dict) or np.shape(members.get(k)) != (K,):
                raise CheckpointError(f"{ckpt}: the checkpoint's per-member bookkeeping lacks {k!r} for {K} members")
        start = serialization.from_state_dict(start, raw["state"])
        ts = jax.device_put(pop.pad(start))
        best_params = serialization.from_state_dict(best_params, raw["best_params"])
        # Copies: arrays restored from msgpack are read-only, these are updated in place.
        best_score = np.array(members["best_score"], np.float64)
        best_chunk = np.array(members["best_chunk"], np.int64)
        diverged = np.array(members["diverged"], np.int64)
        chunks_done = raw["book"]["chunks_done"]
        wall_before = F.resumed_clock(ckpt, book_path, chunks_done, total_chunks)
        rows = F.read_metrics_rows(metrics_path, chunks_done)
        atomic_write(metrics_path, "".join(json.dumps(r) + "\n" for r in rows))

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total_chunks, initial=chunks_done, unit="chunk", dynamic_ncols=True,
                   desc=f"train population of {K} ({len(pop.devices)} device(s))")
    steps_per_update = pop.trainer.steps_per_update
    try:
        while chunks_done < total_chunks and (pop.active(ts) & (diverged == 0)).any():
            t0 = time.perf_counter()
            ts, m, score, finite = pop.chunk(ts)
            m, score, finite = np.asarray(m), np.asarray(score), np.asarray(finite)
            chunks_done += 1
            seconds = time.perf_counter() - t0
            wall = wall_before + time.perf_counter() - t_start
            updates, episodes = np.asarray(ts.update), np.asarray(ts.episodes)
            members = []
            for i in range(K):
                ok = bool(finite[i]) and diverged[i] == 0
                if not ok and diverged[i] == 0:
                    diverged[i] = chunks_done
                row = F.chunk_row(m[i], _Counters(updates[i], episodes[i]),
                                   int(updates[i]) * steps_per_update, chunks_done, wall, seconds)
                row.update(seed=pop.seeds[i], diverged=not ok, validation_success_raw=float(score[i]) if ok else None)
                members.append(row)
                if ok and score[i] >= best_score[i]:       # later chunks win ties, as for one agent
                    best_score[i], best_chunk[i] = float(score[i]), chunks_done
                    best_params = jax.tree.map(lambda b, p: _set(b, i, np.asarray(p)[i]), best_params, ts.params)
            lead = choose(best_score, best_chunk, diverged)
            row = {"chunk": chunks_done, "wall_s": wall, "best_member": lead,
                   "env_steps_per_s": float(sum(r["env_steps_per_s"] for r in members)), "members": members}
            rows.append(row)
            append_line(metrics_path, json.dumps(row) + "\n")
            if (diverged > 0).all():
                break     # no checkpoint of a state in which every member diverged: nothing left to train
            lead_i = lead if lead is not None else 0
            bookkeeping = {"seed": seed, "chunks_done": chunks_done, "best_score": float(best_score[lead_i]),
                           "best_chunk": int(best_chunk[lead_i]), "devices": len(pop.devices), "population": K}
            F.checkpoint_write(ckpt, pack_checkpoint(serialization.msgpack_serialize({
                "state": serialization.to_state_dict(pop.real(ts)),
                "best_params": serialization.to_state_dict(best_params),
                "members": {"best_score": best_score, "best_chunk": best_chunk, "diverged": diverged},
                "book": bookkeeping, "config_toml": config_to_toml(cfg)})))
            F.checkpoint_write(book_path, json.dumps({**bookkeeping, "train_seconds": wall}, indent=1).encode())
            if bar is not None:
                bar.update(1)
                bar.set_postfix(best=f"seed {pop.seeds[lead_i]}: {best_score[lead_i]:.3f}",
                                val=" ".join(f"{s:.2f}" for s in score[:K]), diverged=int((diverged > 0).sum()))
    finally:
        if bar is not None:
            bar.close()
    train_seconds = wall_before + time.perf_counter() - t_start

    if choose(best_score, best_chunk, diverged) is None:
        if rows:
            plot_population_curve(out / "training_curve.png", rows, None)
        raise TrainingDiverged(
            f"every member of the population of {K} diverged (non-finite loss or parameters; {metrics_path}: the "
            f"members' \"diverged\"), and a diverged member is never exported, so no policy was. Lower train.lr "
            f"(it is {cfg.train.lr:g}) or train.max_grad_norm")
    member_params = lambda i: jax.tree.map(lambda x: np.asarray(x)[i], best_params)  # noqa: E731
    t_select = time.perf_counter()
    exported, selection = _choose_for_wearer(cfg, out, pop, best_score, best_chunk, diverged, member_params)
    select_seconds = time.perf_counter() - t_select
    if rows:
        plot_population_curve(out / "training_curve.png", rows, exported)
    F.export_policy(out / "policy.npz", cfg, pop.trainer, member_params(exported))
    # Each member scored by the same compiled evaluation, one at a time (its figures never depend on K).
    evaluate_params = make_evaluator(cfg, pop.trainer.net, eval_episodes or cfg.train.eval_episodes)
    figures = [evaluate_params(member_params(i)) if best_chunk[i] > 0 else None for i in range(K)]
    updates, episodes = np.asarray(ts.update)[:K], np.asarray(ts.episodes)[:K]
    members = []
    for i in range(K):
        f = figures[i]
        members.append({
            "seed": pop.seeds[i],
            "validation_curve": [r["members"][i]["validation_success_raw"] for r in rows],
            "selected_chunk": int(best_chunk[i]),
            "validation_success_raw": float(best_score[i]) if best_chunk[i] else None,
            "diverged_chunk": int(diverged[i]) or None,
            "episodes": int(episodes[i]), "env_steps": int(updates[i]) * steps_per_update,
            "test": None if f is None else {k: f[k] for k in ("accuracy", "success_raw", "reached_goal", "held_out",
                                                              "mean_steps", "by_obstacle")},
        })
    result = dict(figures[exported])
    result.update({"episodes": int(episodes[exported]), "env_steps": int(updates[exported]) * steps_per_update,
                   "train_seconds": round(train_seconds, 3), "seed": pop.seeds[exported], "base_seed": seed,
                   "selected_chunk": int(best_chunk[exported]), "validation_success_raw": float(best_score[exported]),
                   "devices": len(pop.devices), "population": K, "exported_member": exported, "members": members,
                   "selection": selection, "selection_seconds": round(select_seconds, 3)})
    atomic_write(out / "eval.json", json.dumps(result, indent=2) + "\n")
    return result


def _choose_for_wearer(cfg: Config, out: Path, pop: Population, best_score, best_chunk, diverged,
                       member_params) -> tuple[int, list[dict]]:
    """The member to export and the selection's record for eval.json: every candidate (a member that
    finished a chunk and never diverged) exported to ``members/seed_<seed>.npz`` and scored as a wearer
    gets it (jaxexo.train.selection); one candidate is exported without a score."""
    from jaxexo.train.selection import Candidate, choose_for_wearer, score_record, wearer_scores

    ok = [i for i in range(pop.size) if diverged[i] == 0 and best_chunk[i] > 0]
    if len(ok) == 1:
        return ok[0], []
    (out / "members").mkdir(exist_ok=True)
    candidates = [Candidate(pop.seeds[i], float(best_score[i]), F.export_policy(
        out / "members" / f"seed_{pop.seeds[i]}.npz", cfg, pop.trainer, member_params(i))) for i in ok]
    scores = wearer_scores(cfg, candidates)
    return ok[choose_for_wearer(scores)], [score_record(s) for s in scores]


def _set(batch: np.ndarray, i: int, value: np.ndarray) -> np.ndarray:
    out = np.array(batch, copy=True)
    out[i] = value
    return out
