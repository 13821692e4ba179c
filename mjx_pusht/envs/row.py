"""One live world's control step on MuJoCo C in Python floats: the gymnasium single envs' step.

`PushTEnv._step_checked` runs `task.episode.control_step` on (N, ...) NumPy arrays: for one world that
is about 60 array calls on one-row arrays around ~35 us of physics, most of an env step. `step_row` is
the same control step for a batch of one live world, written out for it: the same `frame_skip` mj_step
calls with every physics step's qpos, qvel and sensordata kept (`_Lockstep._step_rows`), the same
invariants folded over them (the shared `weld_gap` and `tee_pose` on the same arrays), the same coverage
(`rules.coverage`), episode bookkeeping, reward, termination and observation, with the scalars in plain
floats. Same bits, every field of the state (tests/test_row_step.py, against the array path over many
episodes of both ids). Where it does not apply it returns None and the caller takes the array path: a
batch of several worlds, a kept (copied) state, an ended episode, the control step holding the settle
step (the invariants' settled values are picked there), a free-joint tee, a study that never terminates.

MuJoCo resets an MjData whose qpos, qvel or qacc went non-finite or past mjMAXVAL, and counts it in
`data.warning`: the states it hands back then look sane. `unstable` reads those counters, and both paths
fold them into `finite`, so a world MuJoCo had to reset is reported (and warned about), never passed on.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjx_pusht.task.invariants import MAX_VAL, WELD_GAP, WORKSPACE, weld_gap
from mjx_pusht.task.rules import POSITION_GAIN, coverage_one, keypoints

# MuJoCo's own divergence test failed (its mj_checkPos / mj_checkVel / mj_checkAcc): it reset the MjData
_RESET_WARNINGS = tuple(int(w) for w in (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                                         mujoco.mjtWarning.mjWARN_BADQACC))
_peak = np.maximum.reduce


def _counters(stepper) -> list:
    """Each MjData's warning counters (views into it, made once per stepper: its MjData never move)."""
    counts = stepper.__dict__.get("_reset_counts")
    if counts is None or len(counts) != len(stepper.datas):
        counts = stepper._reset_counts = [d.warning.number for d in stepper.datas]
    return counts


def unstable(stepper) -> np.ndarray:
    """Per world of a `_Lockstep`: MuJoCo found its state non-finite or past mjMAXVAL since the episode began
    (and reset it)."""
    w1, w2, w3 = _RESET_WARNINGS
    return np.array([bool(n[w1] or n[w2] or n[w3]) for n in _counters(stepper)], bool)


def _nanmax(a, b):
    """np.maximum of two floats: NaN in either gives NaN (Python's max would drop it)."""
    return a if a >= b or a != a else b


def _inside(layout, qs, bounded: bool) -> bool:
    """Every physics step's tee and pusher inside the walls: `invariants_fold`'s containment."""
    return float(_peak(abs(layout.pusher_xy(qs)), axis=None)) < WORKSPACE and _tee_inside(layout, qs, bounded)


def _tee_inside(layout, qs, bounded: bool) -> bool:
    """Every physics step's tee inside the walls: the containment of `layout.tee_pose(qs)`. With
    the T turning about an anchor, the origin is within 2 (|ax| + |ay|) of the hinge's joints: where every
    entry of qs is finite (`bounded`) and the joints stay that far inside, the origin did, with no pose to
    compute (exact)."""
    i = layout.tee[0]
    if bounded and layout.tee[1] == i + 1 and layout.anchor is not None:
        hinge = float(_peak(abs(qs[..., i : i + 2]), axis=None))
        if hinge < WORKSPACE - 2 * (abs(layout.anchor[0]) + abs(layout.anchor[1])) - 1e-9:
            return True
    return float(_peak(abs(layout.tee_pose(qs)[..., :2]), axis=None)) < WORKSPACE


def _tee_pose(layout, q: list) -> list:
    """`layout.tee_pose` of one qpos row in floats (NumPy's cos and sin of the yaw, as the array code's)."""
    x, y, yaw = (q[i] for i in layout.tee)
    if layout.anchor is None:
        return [x, y, yaw]
    ax, ay = layout.anchor
    c, s = float(np.cos(yaw)), float(np.sin(yaw))
    return [x + (ax - (c * ax - s * ay)), y + (ay - (s * ax + c * ay)), yaw]


def applies(env, state) -> bool:
    """The row step computes this env's control step for this state (else: the array path)."""
    data = state.data
    return (env.backend == "cpu" and not env.keep_states and len(state.step) == 1 and env.layout.tee is not None
            and env.episode.terminate and len(getattr(data, "datas", ())) == 1
            and "goal" not in state.carry)  # its coverage is the fixed target's


def step_row(env, state, x: float, y: float):
    """`env._step_checked(state, [[x, y]])` for one live world (`applies`), the same bits; None where the row
    is not live or this control step holds the settle step (the caller takes the array path)."""
    carry = state.carry
    ep, inv = carry["ep"], carry["inv"]
    if ep["done"][0]:
        return None
    k = int(state.step[0])
    fs, settle = env.episode.frame_skip, env._settle
    if k * fs <= settle < (k + 1) * fs:
        return None
    stepper, layout = state.data, env.layout
    # task.to_ctrl on floats: velocity as given, position tracked, target handed to the servos as it is
    q_last = stepper.qpos[-1, 0]
    px, py = float(q_last[layout.pusher[0]]), float(q_last[layout.pusher[1]])
    if env.action_type == "target":
        u = (x if x - x == 0 else px, y if y - y == 0 else py)  # (x - x == 0: finite)
    else:
        if env.action_type == "position":
            x, y = POSITION_GAIN * (x - px), POSITION_GAIN * (y - py)
        u = tuple(min(max(v if v - v == 0 else 0.0, -1.0), 1.0) for v in (x, y))
    stepper._step_rows((u,), (0,))
    qs, vs, ss = stepper.qpos, stepper.qvel, stepper.sens  # (frame_skip, 1, ...): every physics step
    # invariants_fold for one row: maxima do not depend on grouping, NaN propagates, NaN and inf fail `<`
    gap_peak = float(_peak(abs(weld_gap(ss[..., 0:3], ss[..., 3:6]) - WELD_GAP), axis=None))
    big = _nanmax(float(_peak(abs(qs), axis=None)), float(_peak(abs(vs), axis=None)))
    contained = bool(inv["contained"][0]) and _inside(layout, qs, big < MAX_VAL)
    w1, w2, w3 = _RESET_WARNINGS
    n = _counters(stepper)[0]
    finite = bool(inv["finite"][0]) and big < MAX_VAL and not (n[w1] or n[w2] or n[w3])
    gap_max = _nanmax(float(inv["gap_max_dev"][0]), gap_peak)
    # after_control_step, then the functional env's _after (no row held: the row is live)
    q = qs[-1, 0].tolist()
    p, t = [q[i] for i in layout.pusher], _tee_pose(layout, q)
    tee, pusher = np.array([t]), np.array([p])
    cov = coverage_one(*t)
    hit = cov >= env.episode.success
    k1 = k + 1
    success = bool(ep["success"][0]) or hit
    sts = int(ep["steps_to_success"][0])
    terminated = hit and success
    truncated = not terminated and k1 >= env.episode.max_steps
    new_ep = {
        "done": np.array([hit or truncated]),
        "success": np.array([success]),
        "steps_to_success": np.array([k1 if hit and sts < 0 else sts], np.int32),
        "length": np.array([k1], np.int32),
        "return": np.array([float(ep["return"][0]) + cov]),
        "coverage": np.array([cov]),
        "best_coverage": np.array([_nanmax(float(ep["best_coverage"][0]), cov)]),
    }
    new_inv = {"tee_settled": inv["tee_settled"], "gap_settled": inv["gap_settled"],
               "gap_max_dev": np.array([gap_max]), "finite": np.array([finite]), "contained": np.array([contained])}
    obs = {"state": np.array([p + t])}
    if env.keypoints:
        obs["keypoints"] = keypoints(tee)
    if env.scene.variant == "gym-pusht":
        vx, vy = layout.pusher
        v = vs[-1, 0]
        obs["pusher_vel"] = np.array([[v[vx], v[vy]]])
    if env.pixels:
        obs["pixels"] = env.renderer(qs[-1].copy())
    return state._replace(
        carry={**carry, "inv": new_inv, "ep": new_ep, "final": tee, "pusher_final": pusher}, obs=obs,
        reward=np.array([cov]), terminated=np.array([terminated]), truncated=np.array([truncated]),
        step=np.array([k1], np.int32))
