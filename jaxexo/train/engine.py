"""The chunk loop of every ``jaxexo train`` run: resume, checkpoints, the divergence rule, the progress
bar, each agent's best chunk, the choice of the agent to export, the export and eval.json.

One agent is a population of one: the loop and the records (jaxexo.train.records) treat K agents
alike, and a ``Placement`` says only where they live (one agent split over the CPU devices,
jaxexo.train.driver.OneAgent; K members vmapped in lanes, jaxexo.train.population.Members). The run
directory's files and checks are jaxexo.train.run_files'; its formats are in docs/training.md.
"""

from __future__ import annotations

import abc
import json
import time
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
from jaxexo.train.records import Agents, ChunkOut, Track
from jaxexo.train.trainer import Hyperparams


class Placement(abc.ABC):
    """Where a run's K agents live: how their state is made, run, saved and restored. Set by a
    subclass: ``trainer`` (one agent's Trainer), ``size`` (K), ``n_devices`` (in the checkpoint)."""

    trainer: Any
    size: int
    n_devices: int

    @abc.abstractmethod
    def init(self):
        """A new run's state, laid out as a chunk returns it."""

    @abc.abstractmethod
    def chunk(self, ts) -> ChunkOut:
        """One chunk of every agent, judged by the divergence rule and scored on the validation layouts."""

    @abc.abstractmethod
    def saved(self, ts):
        """The TrainState a checkpoint holds: one agent's, or the K members' with a leading axis."""

    @abc.abstractmethod
    def check_resume(self, raw: dict, ckpt: Path) -> None:
        """Refuse a checkpoint this placement cannot continue (before anything is compiled)."""

    @abc.abstractmethod
    def resume(self, saved):
        """The state to continue from, given a checkpoint's ``saved`` TrainState."""


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
        self.agents = Agents(cfg, seed, place.size)
        self.hyper = Hyperparams.from_config(cfg)
        # The budget check before each chunk: one compiled program (tests/test_compile_once.py).
        self._active = jax.jit(place.trainer.active)
        self.ckpt, self.book_path, self.metrics_path = (
            out / F.CHECKPOINT,
            out / F.BOOKKEEPING,
            out / "metrics.jsonl",
        )
        self.rows: list[dict] = []
        self.chunks_done, self.wall_before, self.train_seconds = 0, 0.0, 0.0

    def _leading(self, tree):
        """``tree`` (one agent's, or the members' with their leading axis) as host arrays [K, ...]."""
        return jax.tree.map(
            lambda x: np.asarray(x)[None] if self.agents.one else np.asarray(x), tree
        )

    def _as_saved(self, tree):
        """[K, ...] host arrays as a checkpoint holds them (one agent's without the agent axis)."""
        return jax.tree.map(lambda x: x[0], tree) if self.agents.one else tree

    def _counts(self, ts) -> F.Counters:
        """Every agent's counters [K]."""
        s, k = self.place.saved(ts), self.place.size
        return F.Counters(
            np.asarray(s.update).reshape(k),
            np.asarray(s.episodes).reshape(k),
            self.place.trainer.steps_per_update,
        )

    def start(self, raw: dict | None, resume: bool) -> None:
        place = self.place
        if raw is not None:
            place.check_resume(raw, self.ckpt)
        ts = place.init()
        self.total = F.chunking(self.cfg, place.trainer)[1]
        saved = place.saved(ts)
        self.track = Track.start(self._leading(saved.params), place.size)
        if resume and raw is None:
            # Rows of a run that never reached its first checkpoint.
            atomic_write(self.metrics_path, "")
        self.ts = ts if raw is None else self._restore(raw, saved)

    def _restore(self, raw: dict, fresh):
        # A checkpoint of another network or state layout (another config's, a foreign file) must not
        # be poured into this one: flax would accept mismatched shapes silently.
        noun = "training state" if self.agents.one else "population state"
        raw = dict(raw, state=F.with_empty_fields(serialization.to_state_dict(fresh), raw["state"]))
        for name, template in (
            ("state", serialization.to_state_dict(fresh)),
            ("best_params", serialization.to_state_dict(fresh.params)),
        ):
            bad = F.tree_mismatch(template, raw[name])
            if bad:
                raise CheckpointError(
                    f"{self.ckpt}: does not fit this config's {noun} ({name}{bad})"
                )
        best = serialization.from_state_dict(fresh.params, raw["best_params"])
        self.track = self._restore_track(raw, self._leading(best))
        ts = self.place.resume(serialization.from_state_dict(fresh, raw["state"]))
        self.chunks_done = raw["book"]["chunks_done"]
        self.wall_before = F.resumed_clock(self.ckpt, self.book_path, self.chunks_done, self.total)
        self.rows = raw["rows"]  # checked against the checkpoint by F.prepare_dir
        # Lines written after the checkpoint are recomputed identically: drop them (a torn last line too).
        atomic_write(self.metrics_path, "".join(F.metrics_line(r) for r in self.rows))
        return ts

    def _restore_track(self, raw: dict, params) -> Track:
        """The checkpoint's Track: one agent's best chunk is the book's (a diverged chunk is never
        checkpointed), the members' their own table. Copies: msgpack's arrays are read-only."""
        if self.agents.one:
            book = raw["book"]
            score, chunk = [book["best_score"]], [book["best_chunk"]]
            return Track(
                params,
                np.array(score, np.float64),
                np.array(chunk, np.int64),
                np.zeros(1, np.int64),
            )
        members, k = raw["members"], self.place.size
        for name in ("best_score", "best_chunk", "diverged"):
            if not isinstance(members, dict) or np.shape(members.get(name)) != (k,):
                raise CheckpointError(
                    f"{self.ckpt}: the checkpoint's per-member bookkeeping lacks {name!r} for {k} members"
                )
        return Track(
            params,
            np.array(members["best_score"], np.float64),
            np.array(members["best_chunk"], np.int64),
            np.array(members["diverged"], np.int64),
        )

    def train(self, progress: bool) -> None:
        bar = None
        if progress:
            from tqdm.auto import tqdm

            t, k = self.cfg.train, self.place.size
            desc = (
                f"train {t.trace} {t.control}"
                if self.agents.one
                else f"train population of {k} ({self.place.n_devices} device(s))"
            )
            bar = tqdm(
                total=self.total,
                initial=self.chunks_done,
                unit="chunk",
                dynamic_ncols=True,
                desc=desc,
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
                    **F.chunk_row(
                        jax.tree.map(lambda x: x[i], out.metrics),
                        jax.tree.map(lambda x: x[i], counts),
                        n,
                        wall,
                        seconds,
                    ),
                    **self.agents.label(i),
                    "diverged": not ok,
                    "validation_success_raw": float(out.score[i]) if ok else None,
                }
            )
            if ok and out.score[i] >= track.score[i]:  # later chunks win ties
                track.score[i], track.chunk[i] = float(out.score[i]), n
                if params is None:
                    params = self._leading(place.saved(out.state).params)
                track.params = jax.tree.map(lambda b, p: _set(b, i, p[i]), track.params, params)
        lead = track.lead()
        row = self.agents.row(n, wall, lead, agent_rows)
        self.rows.append(row)
        append_line(self.metrics_path, F.metrics_line(row))
        stopped = bool((track.diverged > 0).all())
        if not stopped:
            # No checkpoint of a state in which every agent diverged: a resume would only diverge again.
            self._checkpoint(wall, lead)
        postfix = self.agents.progress(row, out, track, stopped)
        if bar is not None:
            if not stopped:
                bar.update(1)
            if postfix is not None:
                bar.set_postfix(**postfix)
        return not stopped

    def _checkpoint(self, wall: float, lead: int | None) -> None:
        """State, best parameters and bookkeeping in one atomic write, checksummed: a run stopped at any
        point resumes from a consistent checkpoint (wall time, which differs run to run, stays out)."""
        track, one = self.track, self.agents.one
        i = lead if lead is not None else 0
        book = {
            "seed": self.seed,
            "chunks_done": self.chunks_done,
            "best_score": float(track.score[i]),
            "best_chunk": int(track.chunk[i]),
            "devices": self.place.n_devices,
            **({} if one else {"population": self.place.size}),
        }
        members = {"best_score": track.score, "best_chunk": track.chunk, "diverged": track.diverged}
        F.checkpoint_write(
            self.ckpt,
            pack_checkpoint(
                serialization.msgpack_serialize(
                    {
                        "state": serialization.to_state_dict(self.place.saved(self.ts)),
                        "best_params": serialization.to_state_dict(self._as_saved(track.params)),
                        **({} if one else {"members": members}),
                        "book": book,
                        "config_toml": config_to_toml(self.cfg),
                    }
                )
            ),
        )
        F.checkpoint_write(
            self.book_path, json.dumps({**book, "train_seconds": wall}, indent=1).encode()
        )

    def _select(self):
        """The agent to export (None: none can be) and, for a population, the wearer's choice
        (jaxexo.train.selection): one agent whose chunk diverged after a finite one exports that chunk."""
        track = self.track
        if self.agents.one:
            return (None if track.diverged[0] and track.chunk[0] == 0 else 0), None
        if track.lead() is None:
            return None, None
        from jaxexo.train.selection import choose_member

        chosen = choose_member(self.cfg, self.out, self.place.trainer, track, self.agents.seeds)
        return chosen.exported, chosen

    def finish(self, eval_episodes) -> dict:
        """Choose, plot, export, evaluate, write eval.json; TrainingDiverged where the run diverged."""
        from jaxexo.plots import training as plots

        place, track, cfg, agents = self.place, self.track, self.cfg, self.agents
        exported, selection = self._select()
        if self.rows:
            path = self.out / "training_curve.png"
            if agents.one:
                plots.plot_training_curve(
                    path, [r for r in self.rows if not r["diverged"]] or self.rows
                )
            else:
                plots.plot_population_curve(path, self.rows, exported)
        if exported is None:
            raise TrainingDiverged(agents.nothing_exported(self.metrics_path, track))
        params = [jax.tree.map(lambda x: x[i], track.params) for i in range(place.size)]
        F.export_policy(self.out / "policy.npz", cfg, place.trainer, params[exported])
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
                **agents.identity(exported),
                "selected_chunk": int(track.chunk[exported]),
                "validation_success_raw": float(track.score[exported]),
                "devices": place.n_devices,
                **agents.report(exported, track, self.rows, counts, figures, selection),
            }
        )
        atomic_write(
            self.out / "eval.json",
            json.dumps(F.json_safe(result), indent=2, allow_nan=False) + "\n",
        )
        if track.diverged[exported]:
            raise TrainingDiverged(agents.diverged_after(self.metrics_path, track))
        return result


def _set(batch: np.ndarray, i: int, value: np.ndarray) -> np.ndarray:
    out = np.array(batch, copy=True)
    out[i] = value
    return out
