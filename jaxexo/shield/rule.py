"""The shield's rule, written once for every array module: the moves the agent may choose from a heel.

Each function takes the array module ``xp`` first, like jaxexo.physics.transition, whose move,
floor and undo conditions it reads. The shield's three forms (jaxexo.shield) decide exactly as
``admissible_moves`` and call its pieces (``forward_ends``, ``end_conditions``, ``clearance_need``,
``moves_keep_clearance``, ``shield_conditions``) where they must stay separate for speed; the
conditions themselves: docs/safety.md#the-shield-the-policy-chooses-only-among-safe-moves.
"""

from __future__ import annotations

import numpy as np

from jaxexo.physics import geometry, kinematics, swept
from jaxexo.physics.actions import NUM_ACTIONS, action_directions, undoes
from jaxexo.physics.transition import heel_moved, keeps_off_floor, move_heel, moves_heel

# The moves with no backward component (0-90 and 270-350 deg): a contiguous head and tail of the action
# list, so the shield's mask is assembled with a static concatenation (no scatter, same for every xp).
FORWARD = np.flatnonzero(action_directions()[:, 0] >= 0.0)
_FORWARD_HEAD = int(np.sum(FORWARD < NUM_ACTIONS // 2))
assert np.array_equal(
    FORWARD, np.r_[0:_FORWARD_HEAD, NUM_ACTIONS - (len(FORWARD) - _FORWARD_HEAD) : NUM_ACTIONS]
)
# m: a move "keeps" the clearance it starts with up to this rounding (vertical moves beside a wall).
SHIELD_SLACK = 1e-6
# Entries of ``ends`` from which NumPy's pruning pays (a batch of rows); for one heel's 19 moves the
# unpruned call is cheaper: NumPy's cost there is its number of calls, not the arithmetic.
PRUNE_FROM = 2 * len(FORWARD) * 16


def forward_moves() -> np.ndarray:
    """(NUM_ACTIONS,) bool: the moves with no backward component, the shield's first condition."""
    out = np.zeros(NUM_ACTIONS, bool)
    out[FORWARD] = True
    return out


def _stacked(f, xs):
    """f over the leading axis of every array in xs at once (the default ``over_moves``)."""
    return f(*xs)


def forward_ends(xp, p, heel_y, heel_z):
    """(..., F, 2): where each forward move (the shield's candidates) takes the heel."""
    dirs = p.directions[FORWARD]
    y, z = move_heel(xp, p, heel_y[..., None], heel_z[..., None], dirs[:, 0], dirs[:, 1])
    return xp.stack([y, z], axis=-1)


def clearance_need(xp, p, c_here):
    """The swept distance a move from a foot at clearance ``c_here`` (...,) must keep: the shield's
    clearance, or the clearance where the foot starts if it is closer, less ``SHIELD_SLACK``."""
    return xp.minimum(p.shield_clearance, c_here) - SHIELD_SLACK


def moves_keep_clearance(
    xp, p, heel_y, heel_z, ends, outline, over_moves=_stacked, pruned=None, c_here=None
):
    """(..., F) bool: the shield's clearance condition for the moves from heel (y, z) to ``ends``
    (..., F, 2): the exact swept distance at least min(shield_clearance, the clearance where the foot
    starts), against ``outline`` (..., K, 2).

    The swept distance alone decides: it is zero for a move into the obstacle and at most the
    clearance at either end, so ">= need" (need <= the start's clearance) is swept_clearance's
    ">= need" whenever the foot starts outside; from inside (never reached under the shield) every
    move passes.

    NumPy's branch (``pruned``: None chooses by the size of ``ends``, from ``PRUNE_FROM``) may be
    given, so that a subset of the moves or rows is decided exactly as in a whole step's call (the
    same decisions either way); ``c_here`` (...,): the heels' foot clearances when already known."""
    here = xp.stack([heel_y, heel_z], axis=-1)
    if c_here is None:
        c_here = geometry.foot_clearance(xp, here, p.foot_length, outline)
    if pruned is None:
        pruned = xp is np and ends.size > PRUNE_FROM
    if pruned:
        return moves_keep_clearance_pruned(p, here, c_here, ends, outline)
    moves = xp.moveaxis(ends, -2, 0)  # the moves' axis first: (F, ..., 2)
    d_move = xp.moveaxis(
        over_moves(
            lambda end: swept.swept_distance(xp, here + 0.0 * end, end, p.foot_length, outline),
            (moves,),
        ),
        0,
        -1,
    )  # (..., F)
    return d_move >= clearance_need(xp, p, c_here)[..., None]


def moves_keep_clearance_pruned(p, here, c_here, ends, outline):
    """``moves_keep_clearance`` in NumPy with the same decisions, computing the exact swept distance
    only where the ends' clearances leave it open: a move whose end is closer than needed fails (the
    swept region contains the foot at the end), and one whose ends satisfy the 1-Lipschitz bound
    (c_here + c_end - |move|) / 2 >= need passes (jaxexo.physics.swept.swept_lower_bound)."""
    c_end = geometry.foot_clearance(np, ends, p.foot_length, outline[..., None, :, :])  # (..., F)
    need = np.broadcast_to(clearance_need(np, p, c_here)[..., None], c_end.shape)
    length = np.sqrt(((ends - here[..., None, :]) ** 2).sum(-1))
    ok = (c_here[..., None] > 0.0) & (
        swept.swept_lower_bound(np, c_here[..., None], c_end, length) >= need
    )
    todo = ~ok & (c_end >= need) & (c_here[..., None] > 0.0)
    if todo.any():
        idx = np.nonzero(todo)
        h0 = np.broadcast_to(here[..., None, :], ends.shape)[idx]
        ol = np.broadcast_to(outline[..., None, :, :], ends.shape[:-1] + outline.shape[-2:])[idx]
        ok[idx] = swept.swept_distance(np, h0, ends[idx], p.foot_length, ol) >= need[idx]
    # a foot starting inside the obstacle (never under the shield): every move passes, as in the
    # unpruned rule (its need is <= 0 and a distance is >= 0)
    return ok | (c_here[..., None] <= 0.0)


def admissible_moves(
    xp, p, heel_y, heel_z, layout, over_moves=_stacked, clear=None, last_action=None
):
    """(..., NUM_ACTIONS) bool: the moves the agent may choose from heel (y, z) (the shield).

    Without the shield (``p.shield`` False, the thesis) every move. With it, a move must
    - not go backward (its direction has no -y component: eq 2.31's condition cannot arise);
    - keep the exact clearance of the whole move (jaxexo.physics.swept) at least ``p.shield_clearance``,
      or, where the foot already starts closer (a stance foot near the obstacle), not bring it closer;
    - end where both legs are inside their joint limits (eq 2.50) and within reach (eq 2.45);
    - not end beyond the goal box's far side (goal_y + goal_tolerance[0]): with no move backward the
      goal could never be reached from there (a dead end, like a collision);
    - not end lower than ``p.floor_clearance`` above the floor outside the goal box's column
      (``keeps_off_floor``): the heel comes down only where it lands, it never scuffs or skims along
      the floor towards the goal;
    - move the heel (``moves_heel``: not a move the ground or the world's bounds cancel) and not undo
      ``last_action`` (..., int; -1 or None: none), the move just made: the only forward move that
      undoes another is straight down after straight up or the reverse, so with this rule the heel's y
      never falls, it rises or falls at one y in one direction only, and no point of a swing is
      visited twice: a greedy swing cannot dither between two heights until the step limit.
    Where no move passes all six, the forward moves that keep the clearance and move the heel are
    offered (a foot stopped short of a wall, in front of an obstacle, goes up again rather than
    pushing into the ground); where none does, those that keep the clearance; where none does
    either, every move (so a greedy choice always exists). The training environment, the
    JAX evaluation and the NumPy generator choose among these moves with the same function.

    ``over_moves(f, xs)`` maps f over the leading (move) axis of the arrays xs; the default evaluates
    all moves in one broadcast call, the JAX environment passes a loop (jax.lax.map), whose working set
    stays in cache (several times faster on a CPU for thousands of environments). ``clear`` (..., F),
    when given, is the clearance condition already known: the NumPy generator passes True for the rows
    whose foot is at least shield_clearance + step_size from the obstacle's bounding box, where no
    move of one step can come closer than shield_clearance (the distance is 1-Lipschitz)."""
    new = forward_ends(xp, p, heel_y, heel_z)  # (..., F, 2)
    if clear is None:
        clear = moves_keep_clearance(xp, p, heel_y, heel_z, new, layout.outline, over_moves)
    ok = shield_conditions(xp, p, heel_y, heel_z, layout, FORWARD, new, clear, last_action)
    for fallback in (clear & moves_heel(xp, heel_y, heel_z, new), clear, True):
        ok = xp.where(xp.any(ok, axis=-1, keepdims=True), ok, fallback)
    shape = ok.shape[:-1]
    back = xp.zeros(shape + (NUM_ACTIONS - len(FORWARD),), dtype=bool)
    mask = xp.concatenate([ok[..., :_FORWARD_HEAD], back, ok[..., _FORWARD_HEAD:]], axis=-1)
    return xp.where(p.shield, mask, True)


def shield_conditions(xp, p, heel_y, heel_z, layout, actions, ends, clear, last_action=None):
    """(..., F) bool: moves ``actions`` ((F,) or (..., F)) from heel (y, z) (...,) to ``ends`` (..., F, 2)
    that pass all of ``admissible_moves``' conditions, the clearance one given as ``clear`` (..., F)."""
    kin = kinematics.leg_state(xp, layout.pivot_y[..., None], ends, p.thigh, p.shin)
    angles = kinematics.both_legs_angles(xp, kin)
    reachable = ~(
        kinematics.legs_outside_limits(xp, angles, p.hip_limits, p.knee_limits)
        | kinematics.leg_too_long(
            xp, kin.leg_swing, kin.leg_stance, p.thigh, p.shin, p.leg_length_tolerance
        )
    )
    ends_ok = end_conditions(
        xp,
        p,
        heel_y[..., None],
        heel_z[..., None],
        ends[..., 0],
        ends[..., 1],
        layout.goal_y[..., None],
    )
    ok = clear & reachable & ends_ok
    if last_action is not None:
        ok = ok & ~undoes(xp, actions, last_action)
    return ok


def end_conditions(xp, p, heel_y, heel_z, end_y, end_z, goal_y):
    """``admissible_moves``' conditions on where a move from heel (y, z) ends (all broadcast): not
    beyond the goal box's far side, off the floor outside the goal column, and the heel moved. The
    scalar form calls it on one move's float32 scalars."""
    return (
        (end_y <= goal_y + p.goal_tolerance[0])
        & heel_moved(xp, heel_y, heel_z, end_y, end_z)
        & keeps_off_floor(xp, p, end_y, end_z, goal_y)
    )
