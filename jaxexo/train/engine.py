"""The chunk loop of every ``jaxexo train`` run: resume, checkpoints, the divergence rule, the progress
bar, each agent's best chunk, the choice of the agent to export, the export and eval.json.

What differs between one agent split over the CPU devices (jaxexo.train.driver.OneAgent) and K members
vmapped in lanes (jaxexo.train.population.Members) is a ``Placement``: how the state is made, saved and
restored, how a chunk runs, and how the run's records read (their formats are the run directory's,
docs/training.md). The directory's files and checks are jaxexo.train.run_files'.
"""

from __future__ import annotations

import abc
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import numpy as np
from flax import serialization

from jaxexo.config import Config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.atomic import append_line, atomic_write
from jaxexo.storage.checkpoint import CheckpointError, pack_checkpoint
from jaxexo.storage.rundir import TrainingDiverged
from jaxexo.train import run_files as F
from jaxexo.train.evaluate import make_evaluator


def finite(xp, ts, metrics):
    """The one divergence rule: a chunk diverged unless its parameters, target parameters and metrics
    (the loss among them) are all finite. ``xp``: numpy on the host, jax.numpy inside a compiled
    program (a population's or a sweep's, per agent)."""
    leaves = jax.tree.leaves((ts.params, ts.target_params, metrics))
    return xp.all(xp.stack([xp.all(xp.isfinite(x)) for x in leaves]))


@dataclass
class Track:
    """Each agent's best chunk so far and the chunk it diverged in: what the export is chosen from and
    what the checkpoint keeps."""

    params: Any  # the best chunks' parameters, in the placement's layout
    score: np.ndarray  # (K,) float64: their greedy validation success; -1 before any chunk
    chunk: np.ndarray  # (K,) int64: which chunk (0: none yet)
    diverged: np.ndarray  # (K,) int64: the chunk the agent diverged in (0: never)

    @classmethod
    def start(cls, params, k: int) -> "Track":
        return cls(params, np.full(k, -1.0), np.zeros(k, np.int64), np.zeros(k, np.int64))

    def candidates(self) -> list[int]:
        """The agents that finished a chunk and never diverged."""
        return [i for i in range(len(self.score)) if self.diverged[i] == 0 and self.chunk[i] > 0]


@dataclass
class ChunkOut:
    """One chunk of every agent, on the host."""

    state: Any  # the placement's state after it
    metrics: np.ndarray  # (K, n_chunk, len(METRICS)): UpdateMetrics.named reads it
    score: np.ndarray  # (K,) greedy validation success (meaningless where not finite)
    finite: np.ndarray  # (K,) bool: the divergence rule (``finite``)


class Placement(abc.ABC):
    """Where a run's K agents live, and the records they leave. Set by a subclass: ``trainer`` (one
    agent's Trainer), ``size`` (K), ``n_devices`` (recorded in the checkpoint), ``noun`` (the state, in
    messages), ``desc`` (the progress bar's), ``book`` (extra bookkeeping fields)."""

    trainer: Any
    size: int
    n_devices: int
    noun: str
    desc: str
    book: dict = {}

    # The state -----------------------------------------------------------------------------------
    @abc.abstractmethod
    def check_resume(self, raw: dict, ckpt: Path) -> None:
        """Refuse a checkpoint this placement cannot continue (before anything is compiled)."""

    @abc.abstractmethod
    def init(self):
        """A new run's state, laid out as a chunk returns it."""

    @abc.abstractmethod
    def saved(self, ts):
        """The part of ``ts`` a checkpoint holds (a TrainState of host or device arrays)."""

    @abc.abstractmethod
    def resume(self, saved):
        """The state to continue from, given a checkpoint's ``saved`` TrainState."""

    @abc.abstractmethod
    def restore_track(self, raw: dict, ckpt: Path, params) -> Track:
        """The checkpoint's Track, holding ``params`` (the restored best parameters)."""

    @abc.abstractmethod
    def track_record(self, track: Track) -> dict:
        """What the checkpoint holds of ``track`` besides its parameters and the book."""

    # A chunk -------------------------------------------------------------------------------------
    @abc.abstractmethod
    def active(self, ts) -> np.ndarray:
        """(K,) bool: whose budget is not spent."""

    @abc.abstractmethod
    def chunk(self, ts) -> ChunkOut:
        """One chunk of every agent, judged by ``finite`` and scored on the validation layouts."""

    @abc.abstractmethod
    def counts(self, ts) -> list:
        """Each agent's run_files.Counters."""

    @abc.abstractmethod
    def keep_best(self, best, ts, i: int):
        """``best`` with agent ``i``'s parameters from ``ts``."""

    @abc.abstractmethod
    def params_of(self, best, i: int):
        """Agent ``i``'s parameters in ``best``."""

    # Records -------------------------------------------------------------------------------------
    @abc.abstractmethod
    def lead(self, track: Track) -> int | None:
        """The agent the run would export now (None: none can be)."""

    @abc.abstractmethod
    def row(self, chunk: int, wall: float, lead: int | None, agent_rows: list[dict]) -> dict:
        """metrics.jsonl's line for a chunk, from each agent's row (``label`` in it)."""

    @abc.abstractmethod
    def label(self, i: int) -> dict:
        """What names agent ``i`` in its row."""

    @abc.abstractmethod
    def progress(
        self, row: dict, out: ChunkOut, track: Track, lead: int | None, stopped: bool
    ) -> dict | None:
        """The progress bar's postfix after a chunk (``stopped``: every agent diverged); None: none."""

    # The end -------------------------------------------------------------------------------------
    @abc.abstractmethod
    def select(self, out: Path, track: Track) -> int | None:
        """The agent to export; None when none can be."""

    @abc.abstractmethod
    def plot(self, path: Path, rows: list[dict], exported: int | None) -> None:
        """training_curve.png."""

    @abc.abstractmethod
    def identity(self, exported: int, seed: int) -> dict:
        """eval.json's fields naming the exported agent."""

    @abc.abstractmethod
    def report(
        self, exported: int, track: Track, rows: list[dict], counts: list, figures: list
    ) -> dict:
        """eval.json's fields after the exported agent's (``figures``: each agent's test figures)."""

    @abc.abstractmethod
    def nothing_exported(self, metrics_path: Path, track: Track) -> str:
        """TrainingDiverged's message when no agent can be exported."""

    @abc.abstractmethod
    def diverged_after(self, metrics_path: Path, track: Track) -> str:
        """TrainingDiverged's message when the exported agent diverged after its best chunk."""


def divergence_remedy(cfg: Config) -> str:
    """The last sentence of every TrainingDiverged message: what to change."""
    return f"Lower train.lr (it is {cfg.train.lr:g}) or train.max_grad_norm"


def run_chunks(
    cfg: Config, out: Path, seed: int, resume: bool, progress: bool, eval_episodes, placement
) -> dict:
    """Train ``placement(cfg, seed)``'s agents in chunks into the (locked) run directory ``out``, export
    and evaluate; return eval.json's content. Raises TrainingDiverged after writing what can be trusted."""
    raw = F.prepare_dir(out, cfg, seed, resume)
    run = _Run(cfg, out, seed, time.perf_counter(), placement(cfg, seed))
    run.start(raw, resume)
    run.train(progress)
    return run.finish(eval_episodes)


class _Run:
    """One run's mutable state: the placement's, its Track, its rows and its clock."""

    def __init__(self, cfg: Config, out: Path, seed: int, t_start: float, place: Placement):
        self.cfg, self.out, self.seed, self.t_start, self.place = cfg, out, seed, t_start, place
        self.ckpt, self.book_path, self.metrics_path = (
            out / F.CHECKPOINT,
            out / F.BOOKKEEPING,
            out / "metrics.jsonl",
        )
        self.rows: list[dict] = []
        self.chunks_done, self.wall_before, self.train_seconds = 0, 0.0, 0.0

    def start(self, raw: dict | None, resume: bool) -> None:
        place = self.place
        if raw is not None:
            place.check_resume(raw, self.ckpt)
        ts = place.init()
        self.total = F.chunking(self.cfg, place.trainer)[1]
        saved = place.saved(ts)
        self.track = Track.start(saved.params, place.size)
        if resume and raw is None:
            atomic_write(
                self.metrics_path, ""
            )  # rows of a run that never reached its first checkpoint
        self.ts = ts if raw is None else self._restore(raw, saved)

    def _restore(self, raw: dict, fresh):
        # A checkpoint of another network or state layout (another config's, a foreign file) must not
        # be poured into this one: flax would accept mismatched shapes silently.
        for name, template in (
            ("state", serialization.to_state_dict(fresh)),
            ("best_params", serialization.to_state_dict(fresh.params)),
        ):
            bad = F.tree_mismatch(template, raw[name])
            if bad:
                raise CheckpointError(
                    f"{self.ckpt}: does not fit this config's {self.place.noun} ({name}{bad})"
                )
        self.track = self.place.restore_track(
            raw, self.ckpt, serialization.from_state_dict(fresh.params, raw["best_params"])
        )
        ts = self.place.resume(serialization.from_state_dict(fresh, raw["state"]))
        self.chunks_done = raw["book"]["chunks_done"]
        self.wall_before = F.resumed_clock(self.ckpt, self.book_path, self.chunks_done, self.total)
        self.rows = F.read_metrics_rows(self.metrics_path, self.chunks_done)
        # Lines written after the checkpoint are recomputed identically: drop them (a torn last line too).
        atomic_write(self.metrics_path, "".join(F.metrics_line(r) for r in self.rows))
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
                desc=self.place.desc,
            )
        try:
            while (
                self.chunks_done < self.total
                and (self.place.active(self.ts) & (self.track.diverged == 0)).any()
            ):
                if not self._chunk(bar):
                    break
        finally:
            if bar is not None:
                bar.close()
        self.train_seconds = self.wall_before + time.perf_counter() - self.t_start

    def _chunk(self, bar) -> bool:
        """One chunk: its row, then a checkpoint unless every agent has diverged. False: stop."""
        place, track = self.place, self.track
        t0 = time.perf_counter()
        out = place.chunk(self.ts)
        self.ts, self.chunks_done = out.state, self.chunks_done + 1
        n, seconds = self.chunks_done, time.perf_counter() - t0
        wall = self.wall_before + time.perf_counter() - self.t_start
        counts, agent_rows = place.counts(out.state), []
        for i in range(place.size):
            ok = bool(out.finite[i]) and track.diverged[i] == 0
            if not ok and track.diverged[i] == 0:
                track.diverged[i] = n
            agent_rows.append(
                {
                    **F.chunk_row(out.metrics[i], counts[i], n, wall, seconds),
                    **place.label(i),
                    "diverged": not ok,
                    "validation_success_raw": float(out.score[i]) if ok else None,
                }
            )
            if ok and out.score[i] >= track.score[i]:  # later chunks win ties
                track.score[i], track.chunk[i] = float(out.score[i]), n
                track.params = place.keep_best(track.params, out.state, i)
        lead = place.lead(track)
        row = place.row(n, wall, lead, agent_rows)
        self.rows.append(row)
        append_line(self.metrics_path, F.metrics_line(row))
        stopped = bool((track.diverged > 0).all())
        if not stopped:
            # No checkpoint of a state in which every agent diverged: a resume would only diverge again.
            self._checkpoint(wall, lead)
        postfix = place.progress(row, out, track, lead, stopped)
        if bar is not None:
            if not stopped:
                bar.update(1)
            if postfix is not None:
                bar.set_postfix(**postfix)
        return not stopped

    def _checkpoint(self, wall: float, lead: int | None) -> None:
        """State, best parameters and bookkeeping in one atomic write, checksummed: a run stopped at any
        point resumes from a consistent checkpoint (wall time, which differs run to run, stays out)."""
        place, track = self.place, self.track
        i = lead if lead is not None else 0
        book = {
            "seed": self.seed,
            "chunks_done": self.chunks_done,
            "best_score": float(track.score[i]),
            "best_chunk": int(track.chunk[i]),
            "devices": place.n_devices,
            **place.book,
        }
        F.checkpoint_write(
            self.ckpt,
            pack_checkpoint(
                serialization.msgpack_serialize(
                    {
                        "state": serialization.to_state_dict(place.saved(self.ts)),
                        "best_params": serialization.to_state_dict(track.params),
                        **place.track_record(track),
                        "book": book,
                        "config_toml": config_to_toml(self.cfg),
                    }
                )
            ),
        )
        F.checkpoint_write(
            self.book_path, json.dumps({**book, "train_seconds": wall}, indent=1).encode()
        )

    def finish(self, eval_episodes) -> dict:
        """Choose, plot, export, evaluate, write eval.json; TrainingDiverged where the run diverged."""
        place, track, cfg = self.place, self.track, self.cfg
        exported = place.select(self.out, track)
        if self.rows:
            place.plot(self.out / "training_curve.png", self.rows, exported)
        if exported is None:
            raise TrainingDiverged(place.nothing_exported(self.metrics_path, track))
        F.export_policy(
            self.out / "policy.npz", cfg, place.trainer, place.params_of(track.params, exported)
        )
        # Every agent scored by the same compiled evaluation, one at a time (its figures never depend on K).
        evaluate = make_evaluator(cfg, place.trainer.net, eval_episodes or cfg.train.eval_episodes)
        figures = [
            evaluate(place.params_of(track.params, i))
            if i == exported or track.chunk[i] > 0
            else None
            for i in range(place.size)
        ]
        counts = place.counts(self.ts)
        result = dict(figures[exported])
        result.update(
            {
                "episodes": int(counts[exported].episodes),
                "env_steps": int(counts[exported].env_steps),
                "train_seconds": round(self.train_seconds, 3),
                **place.identity(exported, self.seed),
                "selected_chunk": int(track.chunk[exported]),
                "validation_success_raw": float(track.score[exported]),
                "devices": place.n_devices,
                **place.report(exported, track, self.rows, counts, figures),
            }
        )
        atomic_write(
            self.out / "eval.json",
            json.dumps(F.json_safe(result), indent=2, allow_nan=False) + "\n",
        )
        if track.diverged[exported]:
            raise TrainingDiverged(place.diverged_after(self.metrics_path, track))
        return result
