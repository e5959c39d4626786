"""The chunk loop of every ``jaxexo train`` run: resume, checkpoints, the divergence rule, the progress
bar, each agent's best chunk, the choice of the agent to export, the export and eval.json.

One agent is a population of one: the loop, the records (jaxexo.train.records) and the run
directory's files treat K agents alike, with a leading agent axis, and a ``Placement`` says only
where they live (jaxexo.train.placements). The files' formats are in docs/training.md.
"""

from __future__ import annotations

import abc
import json
import math
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np
from flax import serialization

from jaxexo.config import Config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.atomic import append_line, atomic_write
from jaxexo.storage.checkpoint import pack_checkpoint
from jaxexo.storage.rundir import TrainingDiverged
from jaxexo.train import checkpoints
from jaxexo.train.evaluate import make_evaluator
from jaxexo.train.export import export_policy
from jaxexo.train.metrics_log import Counters, chunk_row, json_safe, metrics_line
from jaxexo.train.records import Agents, ChunkOut, Track
from jaxexo.train.run_dir import BOOKKEEPING, CHECKPOINT, LOG, prepare_dir
from jaxexo.train.trainer import Hyperparams, Trainer

# Aim for chunks of about this many env steps: frequent enough for a live progress bar.
CHUNK_ENV_STEPS = 1_000_000


def chunking(cfg: Config, trainer: Trainer) -> tuple[int, int]:
    """(updates per chunk, chunks): every chunk has the same length, so one program is compiled;
    updates past the budget are masked inside the program."""
    per = cfg.train.num_envs * cfg.train.rollout_steps
    target = cfg.train.chunk_updates or max(1, CHUNK_ENV_STEPS // per)
    chunks = math.ceil(trainer.num_updates / min(target, trainer.num_updates))
    return math.ceil(trainer.num_updates / chunks), chunks


class Placement(abc.ABC):
    """Where a run's K agents live: how their state is made, run, saved and restored. Set by a
    subclass: ``trainer`` (one agent's Trainer), ``size`` (K), ``n_devices`` (in the checkpoint),
    ``title`` (the progress bar's)."""

    trainer: Any
    size: int
    n_devices: int
    title: str

    @abc.abstractmethod
    def init(self):
        """A new run's state, laid out as a chunk returns it."""

    @abc.abstractmethod
    def chunk(self, ts) -> ChunkOut:
        """One chunk of every agent, judged by the divergence rule and scored on the validation layouts."""

    @abc.abstractmethod
    def saved(self, ts):
        """The K agents' TrainState as a checkpoint holds it: host arrays [K, ...]."""

    @abc.abstractmethod
    def check_resume(self, raw: dict, ckpt: Path) -> None:
        """Refuse a checkpoint this placement cannot continue (before anything is compiled)."""

    @abc.abstractmethod
    def resume(self, saved):
        """The state to continue from, given a checkpoint's ``saved`` TrainState [K, ...]."""


def run_chunks(
    cfg: Config, out: Path, seed: int, resume: bool, progress: bool, eval_episodes, placement
) -> dict:
    """Train ``placement(cfg, seed)``'s agents in chunks into the (locked) run directory ``out``, export
    and evaluate; return eval.json's content. Raises TrainingDiverged after writing what can be trusted."""
    raw = prepare_dir(out, cfg, seed, resume)
    run = _Run(cfg, out, seed, time.perf_counter(), placement(cfg, seed))
    run.start(raw, resume)
    run.train(progress)
    return run.finish(eval_episodes)


class _Run:
    """One run's mutable state: the placement's, its Track, its rows and its clock."""

    def __init__(self, cfg: Config, out: Path, seed: int, t_start: float, place: Placement):
        self.cfg, self.out, self.seed, self.t_start, self.place = cfg, out, seed, t_start, place
        self.agents = Agents(cfg, seed, place.size)
        self.hyper = Hyperparams.from_config(cfg)
        # The budget check before each chunk: one compiled program (tests/test_compile_once.py).
        self._active = jax.jit(place.trainer.active)
        self.ckpt, self.book_path, self.metrics_path = (
            out / CHECKPOINT,
            out / BOOKKEEPING,
            out / LOG,
        )
        self.rows: list[dict] = []
        self.chunks_done, self.wall_before, self.train_seconds = 0, 0.0, 0.0

    def _counts(self, ts) -> Counters:
        """Every agent's counters [K]."""
        s = self.place.saved(ts)
        return Counters(s.update, s.episodes, self.place.trainer.steps_per_update)

    def start(self, raw: dict | None, resume: bool) -> None:
        place = self.place
        if raw is not None:
            place.check_resume(raw, self.ckpt)
        ts = place.init()
        self.total = chunking(self.cfg, place.trainer)[1]
        saved = place.saved(ts)
        self.track = Track.start(saved.params, place.size)
        if resume and raw is None:
            # Rows of a run that never reached its first checkpoint.
            atomic_write(self.metrics_path, "")
        self.ts = ts if raw is None else self._restore(raw, saved)

    def _restore(self, raw: dict, fresh):
        state, self.track = checkpoints.restored(raw, fresh, self.ckpt)
        ts = self.place.resume(state)
        self.chunks_done = raw["book"]["chunks_done"]
        self.wall_before = checkpoints.resumed_clock(
            self.ckpt, self.book_path, self.chunks_done, self.total
        )
        self.rows = raw["rows"]  # checked against the checkpoint by prepare_dir
        # Lines written after the checkpoint are recomputed identically: drop them (a torn last line too).
        atomic_write(self.metrics_path, "".join(metrics_line(r) for r in self.rows))
        return ts

    def train(self, progress: bool) -> None:
        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(
                total=self.total,
                initial=self.chunks_done,
                unit="chunk",
                dynamic_ncols=True,
                desc=self.place.title,
            )
        try:
            while self.chunks_done < self.total and self._going():
                if not self._chunk(bar):
                    break
        finally:
            if bar is not None:
                bar.close()
        self.train_seconds = self.wall_before + time.perf_counter() - self.t_start

    def _going(self) -> bool:
        """Whether an agent has budget left and has not diverged."""
        active = np.asarray(self._active(self._counts(self.ts), self.hyper))
        return bool((active & (self.track.diverged == 0)).any())

    def _chunk(self, bar) -> bool:
        """One chunk: its row, then a checkpoint unless every agent has diverged. False: stop."""
        place, track = self.place, self.track
        t0 = time.perf_counter()
        out = place.chunk(self.ts)
        self.ts, self.chunks_done = out.state, self.chunks_done + 1
        n, seconds = self.chunks_done, time.perf_counter() - t0
        wall = self.wall_before + time.perf_counter() - self.t_start
        counts, agent_rows, params = self._counts(out.state), [], None
        for i in range(place.size):
            ok = bool(out.finite[i]) and track.diverged[i] == 0
            if not ok and track.diverged[i] == 0:
                track.diverged[i] = n
            agent_rows.append(
                {
                    **chunk_row(
                        jax.tree.map(lambda x: x[i], out.metrics),
                        jax.tree.map(lambda x: x[i], counts),
                        n,
                        wall,
                        seconds,
                    ),
                    "seed": self.seed + i,
                    "diverged": not ok,
                    "validation_success_raw": float(out.score[i]) if ok else None,
                }
            )
            if ok and out.score[i] >= track.score[i]:  # later chunks win ties
                track.score[i], track.chunk[i] = float(out.score[i]), n
                if params is None:
                    params = place.saved(out.state).params
                track.params = jax.tree.map(lambda b, p: _set(b, i, p[i]), track.params, params)
        lead = track.lead()
        row = self.agents.row(n, wall, lead, agent_rows)
        self.rows.append(row)
        append_line(self.metrics_path, metrics_line(row))
        stopped = bool((track.diverged > 0).all())
        if not stopped:
            # No checkpoint of a state in which every agent diverged: a resume would only diverge again.
            self._checkpoint(wall, lead)
        if bar is not None:
            if not stopped:
                bar.update(1)
            bar.set_postfix(**self.agents.progress(out, track))
        return not stopped

    def _checkpoint(self, wall: float, lead: int | None) -> None:
        """State, best parameters and bookkeeping in one atomic write, checksummed: a run stopped at any
        point resumes from a consistent checkpoint (wall time, which differs run to run, stays out)."""
        track = self.track
        i = lead if lead is not None else 0
        book = {
            "seed": self.seed,
            "chunks_done": self.chunks_done,
            "best_score": float(track.score[i]),
            "best_chunk": int(track.chunk[i]),
            "devices": self.place.n_devices,
            "population": self.place.size,
        }
        members = {"best_score": track.score, "best_chunk": track.chunk, "diverged": track.diverged}
        payload = {
            "state": serialization.to_state_dict(self.place.saved(self.ts)),
            "best_params": serialization.to_state_dict(track.params),
            "members": members,
            "book": book,
            "config_toml": config_to_toml(self.cfg),
        }
        checkpoints.write_checkpoint(
            self.ckpt,
            self.book_path,
            pack_checkpoint(serialization.msgpack_serialize(payload)),
            book,
            wall,
        )

    def _select(self):
        """(the agent to export, None where none can be; the Selection): the wearer's choice among the
        agents that never diverged (jaxexo.train.selection); where every agent diverged, the best
        finite chunk of any (exported, then TrainingDiverged)."""
        from jaxexo.train.selection import Selection, choose_member

        track = self.track
        if track.lead() is None:
            return track.best_finite(), Selection(track.best_finite(), [], 0.0)
        chosen = choose_member(self.cfg, self.out, self.place.trainer, track, self.agents.seeds)
        return chosen.exported, chosen

    def finish(self, eval_episodes) -> dict:
        """Choose, plot, export, evaluate, write eval.json; TrainingDiverged where the run diverged."""
        from jaxexo.plots.training import plot_training_curve

        place, track, cfg, agents = self.place, self.track, self.cfg, self.agents
        exported, selection = self._select()
        if self.rows:
            plot_training_curve(self.out / "training_curve.png", self.rows, exported)
        if exported is None:
            raise TrainingDiverged(agents.nothing_exported(self.metrics_path, track))
        params = [jax.tree.map(lambda x: x[i], track.params) for i in range(place.size)]
        export_policy(self.out / "policy.npz", cfg, place.trainer, params[exported])
        # Every agent scored by the same compiled evaluation, one at a time (its figures never depend on K).
        evaluate = make_evaluator(cfg, place.trainer.net, eval_episodes or cfg.train.eval_episodes)
        figures = [
            evaluate(params[i]) if i == exported or track.chunk[i] > 0 else None
            for i in range(place.size)
        ]
        counts = self._counts(self.ts)
        result = dict(figures[exported])
        result.update(
            {
                "episodes": int(counts.episodes[exported]),
                "env_steps": int(counts.env_steps[exported]),
                "train_seconds": round(self.train_seconds, 3),
                "seed": self.seed + exported,
                "base_seed": self.seed,
                "selected_chunk": int(track.chunk[exported]),
                "validation_success_raw": float(track.score[exported]),
                "devices": place.n_devices,
                **agents.report(exported, track, self.rows, counts, figures, selection),
            }
        )
        atomic_write(
            self.out / "eval.json",
            json.dumps(json_safe(result), indent=2, allow_nan=False) + "\n",
        )
        if track.diverged[exported]:
            raise TrainingDiverged(agents.diverged_after(self.metrics_path, track, exported))
        return result


def _set(batch: np.ndarray, i: int, value: np.ndarray) -> np.ndarray:
    out = np.array(batch, copy=True)
    out[i] = value
    return out
