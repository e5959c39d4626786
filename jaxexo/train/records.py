"""What a ``jaxexo train`` run records of its K agents, written once for any K (one agent is K = 1):
the chunk's metrics line, the progress bar's postfix, eval.json's fields and the TrainingDiverged
messages. Their formats are the run directory's (docs/training.md)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from jaxexo.config import Config


@dataclass
class Track:
    """Each agent's best chunk so far and the chunk it diverged in: what the export is chosen from and
    what the checkpoint keeps (updated in place after every chunk)."""

    params: Any  # [K, ...] host arrays: the best chunks' parameters
    score: np.ndarray  # [K] float64: their greedy validation success; -1 before any chunk
    chunk: np.ndarray  # [K] int64: which chunk (0: none yet)
    diverged: np.ndarray  # [K] int64: the chunk the agent diverged in (0: never)

    @classmethod
    def start(cls, params, k: int) -> "Track":
        return cls(params, np.full(k, -1.0), np.zeros(k, np.int64), np.zeros(k, np.int64))

    def candidates(self) -> list[int]:
        """The agents that finished a chunk and never diverged."""
        return [i for i in range(len(self.score)) if self.diverged[i] == 0 and self.chunk[i] > 0]

    def lead(self) -> int | None:
        """The best candidate on validation (the lowest index on a tie); None if there is none."""
        return self._best(self.candidates())

    def best_finite(self) -> int | None:
        """The agent with the best finite chunk, diverged later or not (the lowest index on a tie);
        None if no chunk was finite."""
        return self._best([i for i in range(len(self.score)) if self.chunk[i] > 0])

    def _best(self, agents: list[int]) -> int | None:
        return max(agents, key=lambda i: (self.score[i], -i)) if agents else None


@dataclass(frozen=True)
class ChunkOut:
    """One chunk of every agent, on the host."""

    state: Any  # the placement's state after it
    metrics: Any  # UpdateMetrics [K, n_chunk]
    score: np.ndarray  # [K] greedy validation success (meaningless where not finite)
    finite: np.ndarray  # [K] bool: the divergence rule (jaxexo.train.lanes.finite)


@dataclass(frozen=True)
class Agents:
    """Who a run trains: seeds ``seed .. seed + K - 1``."""

    cfg: Config
    seed: int
    size: int

    @property
    def seeds(self) -> list[int]:
        return list(range(self.seed, self.seed + self.size))

    def row(self, chunk: int, wall: float, lead: int | None, agent_rows: list[dict]) -> dict:
        """metrics.jsonl's line for a chunk, from each agent's row."""
        return {
            "chunk": chunk,
            "wall_s": wall,
            "best_member": lead,
            "env_steps_per_s": float(sum(r["env_steps_per_s"] for r in agent_rows)),
            "members": agent_rows,
        }

    def progress(self, out: ChunkOut, track: Track) -> dict:
        """The progress bar's postfix after a chunk: the best agent so far, each agent's validation
        success, how many diverged."""
        lead = track.lead()
        return dict(
            best="-" if lead is None else f"seed {self.seed + lead}: {track.score[lead]:.3f}",
            val=" ".join(f"{s:.2f}" for s in out.score),
            diverged=int((track.diverged > 0).sum()),
        )

    def report(self, exported: int, track: Track, rows: list[dict], counts, figures, selection):
        """eval.json's last fields (``counts``: Counters [K]; ``figures``: each agent's test figures;
        ``selection``: jaxexo.train.selection.Selection)."""
        keys = ("accuracy", "success_raw", "reached_goal", "held_out", "mean_steps", "by_obstacle")
        members = [
            {
                "seed": self.seed + i,
                "validation_curve": [r["members"][i]["validation_success_raw"] for r in rows],
                "selected_chunk": int(track.chunk[i]),
                "validation_success_raw": float(track.score[i]) if track.chunk[i] else None,
                "diverged_chunk": int(track.diverged[i]) or None,
                "episodes": int(counts.episodes[i]),
                "env_steps": int(counts.env_steps[i]),
                "test": None if figures[i] is None else {k: figures[i][k] for k in keys},
            }
            for i in range(self.size)
        ]
        return {
            "population": self.size,
            "exported_member": exported,
            "members": members,
            "selection": selection.scores,
            "selection_seconds": round(selection.seconds, 3),
        }

    def nothing_exported(self, metrics_path: Path, track: Track) -> str:
        """TrainingDiverged's message when no agent can be exported (every one diverged before a
        finite chunk)."""
        return self._diverged(
            metrics_path,
            track,
            "no chunk finished with finite parameters, so no policy was exported",
        )

    def diverged_after(self, metrics_path: Path, track: Track, exported: int) -> str:
        """TrainingDiverged's message when every agent diverged and the exported one did so after
        its best chunk."""
        return self._diverged(
            metrics_path,
            track,
            f"policy.npz and eval.json hold the best finite parameters, from chunk "
            f"{track.chunk[exported]} of seed {self.seed + exported} (validation success on raw "
            f"moves {track.score[exported]:.3f})",
        )

    def _diverged(self, metrics_path: Path, track: Track, what: str) -> str:
        n = int(track.diverged.max())
        return (
            f"training diverged in chunk {n} (non-finite loss or parameters; {metrics_path} row {n} "
            f'has "diverged": true for every member); {what}. {divergence_remedy(self.cfg)}'
        )


def divergence_remedy(cfg: Config) -> str:
    """The last sentence of every TrainingDiverged message: what to change."""
    return f"Lower train.lr (it is {cfg.train.lr:g}) or train.max_grad_norm"
