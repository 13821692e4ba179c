"""The invariants: the weld gap and the rigidity verdict, written once for NumPy and JAX."""

from __future__ import annotations

import numpy as np

from mjx_pusht.task.rules import array_namespace

WELD_GAP = 0.06  # bar centre to stem centre in the authored T, metres
RIGID_TOL = 1e-4  # peak |gap - 0.06| below this over the whole run: one rigid body
WORKSPACE = 0.40  # the walls' inner faces are at +-0.39 m: a tee or pusher centre beyond this went through a wall
MAX_VAL = 1e10  # MuJoCo's mjMAXVAL: a state beyond it has diverged even while still finite


def weld_gap(bar_pos, stem_pos):
    """World distance between the bar and stem geom centres; (..., 3) arrays of either kind."""
    d = bar_pos - stem_pos
    return ((d * d).sum(axis=-1)) ** 0.5


def gap_deviation(bar_pos, stem_pos):
    """|gap - 0.06|: exactly 0 for a welded T at every step, large for a split one."""
    return abs(weld_gap(bar_pos, stem_pos) - WELD_GAP)


def stayed_rigid(gap_max_dev):
    """The verdict keys off the whole-run peak deviation; NaN (a diverged run) is never rigid."""
    return gap_max_dev < RIGID_TOL



def invariants_init(n: int, xp):
    """The running reduction's start: nothing settled yet, zero peak, all finite."""
    nan = xp.full((n,), float("nan"))
    return {
        "tee_settled": xp.stack([nan, nan, nan], axis=-1),
        "gap_settled": nan,
        "gap_max_dev": xp.zeros((n,)),
        "finite": xp.ones((n,), dtype=bool),
        "contained": xp.ones((n,), dtype=bool),
    }


def sane(x):
    """Per row: every entry finite and within MuJoCo's mjMAXVAL (its own divergence test)."""
    xp = array_namespace(x)
    return xp.all(xp.isfinite(x) & (abs(x) < MAX_VAL), axis=-1)


def invariants_update(acc, t, settle_step, tee_pose, pusher_xy, qpos, qvel, bar_pos, stem_pos):
    """Fold one step into the running invariants; used per step by every backend.

    `bar_pos`/`stem_pos` are the geom positions MuJoCo computed in step t (the
    kinematics of the pre-step state, as the chapter reads geom_xpos after
    mj_step); `qpos` and `tee_pose` are the state after step t. The settled
    values are those after step `settle_step` (the last settle step).
    """
    xp = array_namespace(qpos)
    gap = weld_gap(bar_pos, stem_pos)
    at_settle = t == settle_step  # a scalar, or per row when rows are at different steps (an env's batch)
    at_pose = at_settle[..., None] if getattr(at_settle, "ndim", 0) else at_settle
    return {
        "tee_settled": xp.where(at_pose, tee_pose, acc["tee_settled"]),
        "gap_settled": xp.where(at_settle, gap, acc["gap_settled"]),
        # maximum propagates NaN, so a diverged seed can never read as rigid
        "gap_max_dev": xp.maximum(acc["gap_max_dev"], abs(gap - WELD_GAP)),
        "finite": acc["finite"] & sane(qpos) & sane(qvel),
        # a tee or a pusher outside the walls means a contact was missed (or the state diverged): a 1e300 kg T
        # once pressed the pusher through the south wall while the T stayed put
        "contained": acc["contained"] & xp.all(abs(tee_pose[..., :2]) < WORKSPACE, axis=-1)
        & xp.all(abs(pusher_xy) < WORKSPACE, axis=-1),
    }


def invariants_fold(acc, t, settle_step, tee_pose, pusher_xy, qpos, qvel, bar_pos, stem_pos):
    """`invariants_update` over consecutive steps at once: every array has a leading axis of steps (the CPU's
    `frame_skip` physics steps of one control step; `t` (S,) or (S, N)). The same values to the bit as S
    updates in turn: maxima and conjunctions do not depend on grouping, and the settled values are picked
    from the step that is `settle_step`, never computed. One call of a few array operations instead of S."""
    xp = array_namespace(qpos)
    gap = weld_gap(bar_pos, stem_pos)  # (S, N)
    # `max` as the maximum ufunc's own reduction on the host (np.max is that, behind a Python wrapper)
    peak = np.maximum.reduce if xp is np else (lambda x, axis: xp.max(x, axis=axis))
    out = {
        "tee_settled": acc["tee_settled"],
        "gap_settled": acc["gap_settled"],
        "gap_max_dev": xp.maximum(acc["gap_max_dev"], peak(abs(gap - WELD_GAP), axis=0)),
        # "every entry finite and below the bound" as one maximum per row: max propagates NaN, and NaN or inf
        # fails `< bound`, so this is `all(sane)` / `all(|xy| < WORKSPACE)` in a third of the array calls
        "finite": acc["finite"] & (xp.maximum(peak(abs(qpos), axis=(0, -1)), peak(abs(qvel), axis=(0, -1)))
                                   < MAX_VAL),
        "contained": acc["contained"] & (peak(abs(tee_pose[..., :2]), axis=(0, -1)) < WORKSPACE)
        & (peak(abs(pusher_xy), axis=(0, -1)) < WORKSPACE),
    }
    at = xp.asarray(t == settle_step)
    # the settle step falls in the first control step only: in every other there is nothing to pick
    if isinstance(at, np.ndarray) and not at.any():
        return out
    at = xp.broadcast_to(at.reshape(at.shape + (1,) * (gap.ndim - at.ndim)), gap.shape)
    hit = xp.any(at, axis=0)
    j = xp.argmax(at, axis=0)
    gap_at = xp.take_along_axis(gap, j[None], axis=0)[0]
    tee_at = xp.take_along_axis(tee_pose, j[None, ..., None], axis=0)[0]
    return {**out, "tee_settled": xp.where(hit[..., None], tee_at, acc["tee_settled"]),
            "gap_settled": xp.where(hit, gap_at, acc["gap_settled"])}
