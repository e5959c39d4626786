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

The chunk loop (resume, the directory lock, checksums, the config checks, the divergence rule) is the
one-agent driver's: jaxexo.train.engine, of which ``Members`` here is the population's placement. A
member whose parameters, target parameters or metrics become non-finite is dropped from the choice
(``diverged_chunk``), not the run; if every member diverges, training stops and TrainingDiverged is
raised as for one agent.
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxexo.config import Config, ConfigError
from jaxexo.storage.atomic import write_figure
from jaxexo.storage.checkpoint import CheckpointError
from jaxexo.train import run_files as F
from jaxexo.train.engine import ChunkOut, Placement, Track, divergence_remedy, finite, run_chunks
from jaxexo.train.evaluate import make_rollouts, validation_set
from jaxexo.train.lanes import LANES, over_lanes, padded_agents
from jaxexo.train.trainer import Hyperparams, Trainer


def population_devices(n_members: int, devices) -> list:
    """The devices a population uses: as many as it fills with whole blocks of LANES members, but at
    least two where there are two. XLA compiles a program over one device without partitioning and
    over several with it, and the two differ in the last bits (measured: a member's bytes are equal
    on 2 and 4 devices, not on 1 and 2), so a population never drops to one device because it is
    small: its members then train as they do in a larger population or a sweep on the same machine."""
    devices = list(devices)
    return devices[: min(len(devices), max(2, -(-n_members // LANES)))]


class Population:
    """The compiled programs of a population of one config: ``init(seeds)`` and ``chunk(state)``.

    The state has a leading member axis padded to ``padded`` (copies of the first member, whose
    results are dropped); ``real(x)`` cuts any output back to the real members."""

    def __init__(self, cfg: Config, seeds, devices=None, n_chunk: int | None = None):
        self.cfg, self.seeds = cfg, [int(s) for s in seeds]
        if not self.seeds:
            raise ConfigError("train.population: a population needs at least one member")
        self.trainer = Trainer(cfg)  # one device per member: no data parallelism inside a member
        self.devices = population_devices(
            len(self.seeds), devices if devices is not None else jax.local_devices()
        )
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
            return ts, m, score, finite(jnp, ts, m)

        self._init = over_lanes(trainer.init, self.devices, n_args=2)
        self._chunk = over_lanes(member, self.devices, n_args=2, shared=2)
        self._active = jax.jit(jax.vmap(trainer.active))

    @property
    def size(self) -> int:
        return len(self.seeds)

    def pad(self, tree):
        """Members -> the padded batch (copies of the first member after the real ones)."""
        extra = self.padded - self.size
        return jax.tree.map(
            lambda x: np.concatenate([np.asarray(x)] + [np.asarray(x)[:1]] * extra), tree
        )

    def real(self, tree):
        return jax.tree.map(lambda x: np.asarray(x)[: self.size], tree)

    def init(self):
        keys = np.stack([np.asarray(jax.random.PRNGKey(s)) for s in self.seeds])
        return self._init(self.pad(keys), self.hyper)

    def chunk(self, ts):
        """One chunk for every member: (state, metrics (padded, n_chunk, len(METRICS)), validation
        success (padded,), finite (padded,))."""
        return self._chunk(ts, self.hyper, self.val_layouts, self.val_params)

    def active(self, ts) -> np.ndarray:
        return np.asarray(self._active(ts, self.hyper))[: self.size]


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
        a2.plot(
            ep,
            [
                np.nan if m["validation_success_raw"] is None else m["validation_success_raw"]
                for m in mem
            ],
            label=label,
            **bold,
        )
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
    ok = Track(None, best_score, best_chunk, diverged).candidates()
    if not ok:
        return None
    return max(ok, key=lambda i: (best_score[i], -i))


def run_population(
    cfg: Config, out: Path, seed: int, resume: bool, progress: bool, eval_episodes
) -> dict:
    """The population driver, called by ``driver.run_training`` (which holds the directory's lock)."""
    from jaxexo.config.memory import check_memory

    check_memory(cfg)
    return run_chunks(cfg, out, seed, resume, progress, eval_episodes, Members)


class Members(Placement):
    """The engine's placement of a population: K members vmapped in lanes (``Population``). Its records:
    per-member rows in each metrics line, per-member bookkeeping in the checkpoint, the member a
    wearer would choose exported, every member in eval.json."""

    noun = "population state"

    def __init__(self, cfg: Config, seed: int):
        self.cfg, self.size = cfg, cfg.train.population
        self.pop = Population(cfg, range(seed, seed + self.size))
        self.trainer, self.n_devices, self.book = (
            self.pop.trainer,
            len(self.pop.devices),
            {"population": self.size},
        )
        self.desc = f"train population of {self.size} ({self.n_devices} device(s))"
        self.selection, self.selection_seconds = [], 0.0

    def check_resume(self, raw, ckpt):
        if "members" not in raw:
            raise CheckpointError(
                f"{ckpt}: a one-agent checkpoint; this config trains a population of {self.size}"
            )
        if (raw["book"]["devices"] == 1) != (self.n_devices == 1):
            # One device compiles an unpartitioned program, several a partitioned one: their arithmetic
            # differs in the last bits (population_devices), so the rest of the run would not be this run's.
            need = "one CPU device" if raw["book"]["devices"] == 1 else "two or more CPU devices"
            raise ConfigError(
                f"--resume: the population ran on {raw['book']['devices']} device(s), this process "
                f"gives it {self.n_devices}; resume it with {need}"
            )

    def init(self):
        return self.pop.init()

    def saved(self, ts):
        return self.pop.real(ts)

    def resume(self, saved):
        return jax.device_put(self.pop.pad(saved))

    def restore_track(self, raw, ckpt, params):
        members, k = raw["members"], self.size
        for name in ("best_score", "best_chunk", "diverged"):
            if not isinstance(members, dict) or np.shape(members.get(name)) != (k,):
                raise CheckpointError(
                    f"{ckpt}: the checkpoint's per-member bookkeeping lacks {name!r} for {k} members"
                )
        # Copies: arrays restored from msgpack are read-only, these are updated in place.
        return Track(
            params,
            np.array(members["best_score"], np.float64),
            np.array(members["best_chunk"], np.int64),
            np.array(members["diverged"], np.int64),
        )

    def track_record(self, track):
        return {
            "members": {
                "best_score": track.score,
                "best_chunk": track.chunk,
                "diverged": track.diverged,
            }
        }

    def active(self, ts):
        return self.pop.active(ts)

    def chunk(self, ts):
        ts, m, score, ok = self.pop.chunk(ts)
        k = self.size
        return ChunkOut(ts, np.asarray(m)[:k], np.asarray(score)[:k], np.asarray(ok)[:k])

    def counts(self, ts):
        updates, episodes = np.asarray(ts.update), np.asarray(ts.episodes)
        per = self.trainer.steps_per_update
        return [
            F.Counters(updates[i], episodes[i], int(updates[i]) * per) for i in range(self.size)
        ]

    def keep_best(self, best, ts, i):
        return jax.tree.map(lambda b, p: _set(b, i, np.asarray(p)[i]), best, ts.params)

    def params_of(self, best, i):
        return jax.tree.map(lambda x: np.asarray(x)[i], best)

    def lead(self, track):
        return choose(track.score, track.chunk, track.diverged)

    def row(self, chunk, wall, lead, agent_rows):
        return {
            "chunk": chunk,
            "wall_s": wall,
            "best_member": lead,
            "env_steps_per_s": float(sum(r["env_steps_per_s"] for r in agent_rows)),
            "members": agent_rows,
        }

    def label(self, i):
        return {"seed": self.pop.seeds[i]}

    def progress(self, row, out, track, lead, stopped):
        if stopped:
            return None
        i = lead if lead is not None else 0
        return dict(
            best=f"seed {self.pop.seeds[i]}: {track.score[i]:.3f}",
            val=" ".join(f"{s:.2f}" for s in out.score),
            diverged=int((track.diverged > 0).sum()),
        )

    def select(self, out, track):
        if choose(track.score, track.chunk, track.diverged) is None:
            return None
        t_select = time.perf_counter()
        exported, self.selection = _choose_for_wearer(
            self.cfg, out, self.pop, track, lambda i: self.params_of(track.params, i)
        )
        self.selection_seconds = time.perf_counter() - t_select
        return exported

    def plot(self, path, rows, exported):
        plot_population_curve(path, rows, exported)

    def identity(self, exported, seed):
        return {"seed": self.pop.seeds[exported], "base_seed": seed}

    def report(self, exported, track, rows, counts, figures):
        members = []
        for i in range(self.size):
            f = figures[i]
            members.append(
                {
                    "seed": self.pop.seeds[i],
                    "validation_curve": [r["members"][i]["validation_success_raw"] for r in rows],
                    "selected_chunk": int(track.chunk[i]),
                    "validation_success_raw": float(track.score[i]) if track.chunk[i] else None,
                    "diverged_chunk": int(track.diverged[i]) or None,
                    "episodes": int(counts[i].episodes),
                    "env_steps": int(counts[i].env_steps),
                    "test": None
                    if f is None
                    else {
                        k: f[k]
                        for k in (
                            "accuracy",
                            "success_raw",
                            "reached_goal",
                            "held_out",
                            "mean_steps",
                            "by_obstacle",
                        )
                    },
                }
            )
        return {
            "population": self.size,
            "exported_member": exported,
            "members": members,
            "selection": self.selection,
            "selection_seconds": round(self.selection_seconds, 3),
        }

    def nothing_exported(self, metrics_path, track):
        return (
            f"every member of the population of {self.size} diverged (non-finite loss or parameters; "
            f'{metrics_path}: the members\' "diverged"), and a diverged member is never exported, so no policy '
            f"was. {divergence_remedy(self.cfg)}"
        )

    def diverged_after(self, metrics_path, track):
        raise AssertionError("a diverged member is never exported")


def _choose_for_wearer(
    cfg: Config, out: Path, pop: Population, track: Track, member_params
) -> tuple[int, list[dict]]:
    """The member to export and the selection's record for eval.json: every candidate (a member that
    finished a chunk and never diverged) exported to ``members/seed_<seed>.npz`` and scored as a wearer
    gets it (jaxexo.train.selection); one candidate is exported without a score."""
    from jaxexo.train.selection import Candidate, choose_for_wearer, score_record, wearer_scores

    ok = track.candidates()
    if len(ok) == 1:
        return ok[0], []
    (out / "members").mkdir(exist_ok=True)
    candidates = [
        Candidate(
            pop.seeds[i],
            float(track.score[i]),
            F.export_policy(
                out / "members" / f"seed_{pop.seeds[i]}.npz", cfg, pop.trainer, member_params(i)
            ),
        )
        for i in ok
    ]
    scores = wearer_scores(cfg, candidates)
    return ok[choose_for_wearer(scores)], [score_record(s) for s in scores]


def _set(batch: np.ndarray, i: int, value: np.ndarray) -> np.ndarray:
    out = np.array(batch, copy=True)
    out[i] = value
    return out
