"""The shield's admissible moves for many heels at once, in the training environment's float32: the
form ``make_shield("rows", ...)`` (jaxexo.shield).

The generator's batch rollout and its reference: ``admissible`` is jaxexo.shield.rule.admissible_moves
on rows of stacked scenes, with the exact swept clearance (jaxexo.physics.swept) computed only for the
heels near the obstacle (elsewhere no move can fail it). ``choose`` is the shielded greedy action,
checking first only each row's best forward moves (one move per row instead of 19, in the same
float32 elementwise arithmetic) and the full mask only for the rows where none of them passes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from jaxexo.physics import actions, geometry, transition
from jaxexo.shield import rule


def take_rows(rec, idx, shared=()):
    """Rows ``idx`` of a record whose fields have a leading axis (stacked scenes, a trajectory
    batch): arrays indexed, tuples row by row; the fields named in ``shared`` (and None) are every
    row's."""
    return type(rec)(
        **{
            k: v
            if k in shared or v is None
            else tuple(v[i] for i in idx)
            if isinstance(v, tuple)
            else v[idx]
            for k, v in (rec._asdict() if hasattr(rec, "_asdict") else vars(rec)).items()
        }
    )


@dataclass
class ShieldStats:
    """The shielded choices of a form's ``choose`` (the generator's ``shield_stats``): one swing's
    steps checked move by move (jaxexo.shield.scalar) and those handed to the full mask; a batch's
    rows (``ShieldRows.choose``, and the JAX form's, which computes every row's mask) and those handed
    to the full mask."""

    steps: int = 0
    steps_to_full_mask: int = 0
    rows: int = 0
    rows_to_full_mask: int = 0


class ShieldRows:
    """Admissible moves of many heels for parameters ``p`` (jaxexo.config.numpy_params) and ``sp``
    (jaxexo.config.scalar_params); ``stats`` (ShieldStats; None: a fresh one) counts the rows
    ``choose`` decides."""

    kind = "rows"
    # forward moves checked one at a time per row before the full mask (``choose``)
    BATCH_ROUNDS = 4

    def __init__(self, p, sp, stats=None):
        self.p, self.sp = p, sp
        self.stats = ShieldStats() if stats is None else stats
        self._fwd_idx = rule.FORWARD
        self._n_forward = len(self._fwd_idx)

    def _near(self, hy, hz, lay) -> np.ndarray:
        """(B,) rows whose foot is within a step plus the shield's clearance of the obstacle's bounding
        box (elsewhere no move can fail the clearance condition)."""
        p = self.p
        half = 0.5 * lay.width
        dy = np.maximum(
            np.maximum(lay.center_y - half - (hy + p.foot_length), hy - (lay.center_y + half)), 0.0
        )
        dz = np.maximum(hz - lay.height, 0.0)
        return np.hypot(dy, dz) < self.sp.shield_clearance + self.sp.step_size + 1e-4

    def _clear(self, hy, hz, ends, outline, pruned: bool, c_here=None) -> np.ndarray:
        """rule.moves_keep_clearance for heels (B,) and move ends (B, F, 2), with its NumPy branch
        (pruned or not: the same decisions) given rather than chosen by the array's size,
        so that a subset of the moves or rows is decided exactly as in the whole step's call.
        ``c_here``: the heels' foot clearances when known (elementwise, so the same numbers)."""
        return rule.moves_keep_clearance(
            np, self.p, hy, hz, ends, outline, pruned=pruned, c_here=c_here
        )

    def admissible(
        self, hy, hz, lay, last_action=None, *, pruned: bool | None = None, near=None, c_here=None
    ) -> np.ndarray:
        """(B, A) the shield's admissible moves (jaxexo.shield.rule.admissible_moves) of many heels,
        float32 rows of stacked scenes like the training environment; the exact clearance is computed
        only for the ``_near`` rows (elsewhere no move can fail it, so the mask is the same).
        ``last_action`` (B,): the moves just made (-1: none; None: no undo condition); ``pruned``: the
        clearance's NumPy branch (None: by size, as moves_keep_clearance chooses); ``c_here`` (B,):
        the heels' foot clearances where ``near``."""
        p = self.p
        near = self._near(hy, hz, lay) if near is None else near
        clear = np.ones((len(hy), self._n_forward), bool)
        if near.any():
            ends = rule.forward_ends(np, p, hy[near], hz[near])
            clear[near] = self._clear(
                hy[near],
                hz[near],
                ends,
                lay.outline[near],
                pruned,
                None if c_here is None else c_here[near],
            )
        return rule.admissible_moves(np, p, hy, hz, lay, clear=clear, last_action=last_action)

    def choose(self, hy, hz, lay, q, last_action) -> np.ndarray:
        """The shielded greedy actions (B,) of ``admissible`` + greedy_action for Q-values ``q``
        (B, A), checking first only each row's best forward move (one move per row instead of 19, in
        the same float32 elementwise arithmetic); the full mask only for the rows where that move is
        not admissible."""
        if not bool(self.p.shield):
            return actions.greedy_action(np, q)
        last = last_action
        fwd = self._fwd_idx
        # forward moves by decreasing Q, ties by index (as argmax over the mask picks the first)
        order = fwd[np.argsort(-q[:, fwd], axis=1, kind="stable")[:, : self.BATCH_ROUNDS]]
        near = self._near(hy, hz, lay)
        # the branch the whole step's moves_keep_clearance call takes (by its array's size)
        pruned = int(near.sum()) * self._n_forward * 2 > rule.PRUNE_FROM
        # the near heels' foot clearances once per step (every round and the full mask read them)
        c_here = np.zeros(len(hy), np.float32)
        if near.any():
            c_here[near] = geometry.foot_clearance(
                np, np.stack([hy[near], hz[near]], axis=-1), self.p.foot_length, lay.outline[near]
            )
        out = order[:, 0].copy()
        miss = np.arange(len(hy))
        for r in range(self.BATCH_ROUNDS):  # the r-th best move of the rows still undecided
            a = order[miss, r]
            ok = self._one_move_ok(
                hy[miss],
                hz[miss],
                take_rows(lay, miss),
                near[miss],
                a,
                pruned,
                last[miss],
                c_here[miss],
            )
            out[miss[ok]] = a[ok]
            miss = miss[~ok]
            if not miss.size:
                break
        if miss.size:
            sub = take_rows(lay, miss)
            mask = self.admissible(
                hy[miss],
                hz[miss],
                sub,
                last[miss],
                pruned=pruned,
                near=near[miss],
                c_here=c_here[miss],
            )
            out[miss] = actions.greedy_action(np, q[miss], mask)
        self.stats.rows += len(hy)
        self.stats.rows_to_full_mask += miss.size
        return out

    def _one_move_ok(self, hy, hz, lay, near, a, pruned: bool, last, c_here=None) -> np.ndarray:
        """(B,) whether move a (B,) passes all of admissible_moves' conditions (its column of the
        mask before the fallbacks; ``last`` (B,) the moves just made, ``c_here`` as ``admissible``),
        in the same float32 elementwise arithmetic."""
        p = self.p
        d = p.directions[a]
        y, z = transition.move_heel(np, p, hy, hz, d[:, 0], d[:, 1])
        new = np.stack([y, z], axis=-1)[:, None, :]  # (B, 1, 2)
        clear = np.ones((len(hy), 1), bool)
        if near.any():
            clear[near] = self._clear(
                hy[near],
                hz[near],
                new[near],
                lay.outline[near],
                pruned,
                None if c_here is None else c_here[near],
            )
        return rule.shield_conditions(np, p, hy, hz, lay, a[:, None], new, clear, last)[:, 0]
