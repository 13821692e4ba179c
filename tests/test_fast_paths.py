"""The CPU env's fast paths give the array code's bits: the invariants folded over a control step's physics
steps at once, and the coverage of a few host poses in plain floats."""

from __future__ import annotations

import numpy as np

from mjx_pusht.task.invariants import invariants_fold, invariants_init, invariants_update
from mjx_pusht.task.rules import T_REACH, _coverage, _coverage_few, coverage_one


def test_folding_the_physics_steps_at_once_equals_folding_them_one_by_one():
    rng = np.random.default_rng(0)
    s, n, nq = 10, 6, 5
    qpos, qvel = rng.normal(size=(s, n, nq)), rng.normal(size=(s, n, nq))
    bar, stem = rng.normal(size=(s, n, 3)), rng.normal(size=(s, n, 3))
    tee = rng.normal(scale=0.3, size=(s, n, 3))
    push = rng.uniform(-0.39, 0.39, size=(s, n, 2))
    push[4, 5, 1] = -0.45  # a pusher through the south wall
    qpos[3, 1, 2] = np.nan  # a world that diverges mid-step
    qvel[7, 2, 0] = 1e11  # beyond mjMAXVAL
    bar[5, 3, 1] = np.nan  # a NaN gap propagates into the peak
    tee[2, 4, 0] = 0.5  # outside the walls
    k = np.array([0, 0, 1, 2, 5, 0])  # rows at different control steps: the settle step falls in some of them
    for settle in (0, 7, 12, 23):
        t = k[None] * s + np.arange(s)[:, None]
        one_by_one = invariants_init(n, np)
        for j in range(s):
            one_by_one = invariants_update(one_by_one, t[j], settle, tee[j], push[j], qpos[j], qvel[j], bar[j], stem[j])
        at_once = invariants_fold(invariants_init(n, np), t, settle, tee, push, qpos, qvel, bar, stem)
        for key in one_by_one:
            np.testing.assert_array_equal(at_once[key], one_by_one[key], err_msg=key)
    scalar_k = invariants_fold(invariants_init(n, np), 3 * s + np.arange(s), 35, tee, push, qpos, qvel, bar, stem)
    np.testing.assert_array_equal(scalar_k["tee_settled"], tee[5])


def test_the_coverage_of_a_few_poses_is_the_array_codes_to_the_bit():
    rng = np.random.default_rng(1)
    n = 4000
    poses = np.stack([rng.uniform(-2 * T_REACH, 2 * T_REACH, n), rng.uniform(-2 * T_REACH, 2 * T_REACH, n),
                      rng.uniform(-np.pi, np.pi, n)], axis=1)
    poses[:50] = 0.0  # on the goal exactly
    poses[50:100, 2] = 0.0  # edges parallel to the target's
    poses[100:150, :2] = np.round(poses[100:150, :2], 2)  # vertices on the target's edges
    poses[150:200, 2] = np.pi / 2
    ref = _coverage(poses)  # the array code every backend runs, without the host's distance shortcut
    few = np.concatenate([_coverage_few(poses[i : i + 1]) for i in range(n)])
    np.testing.assert_array_equal(few, ref)
    assert (ref > 0).sum() > n // 5 and (ref == 1).sum() >= 50  # overlaps of every kind were compared
    np.testing.assert_array_equal([coverage_one(*p) for p in poses.tolist()], ref)  # one pose, floats in and out
    target = np.array([0.05, -0.02, 0.7])  # another target pose, given once for all rows and row by row
    ref = _coverage(poses, np.broadcast_to(target, poses.shape))
    np.testing.assert_array_equal(np.concatenate([_coverage_few(poses[i : i + 1], target) for i in range(n)]), ref)
    np.testing.assert_array_equal(_coverage_few(poses[:3], np.broadcast_to(target, (3, 3))), ref[:3])


def test_the_folded_finite_and_containment_verdicts_hold_for_every_kind_of_bad_value():
    """The fold's per-row maximum against the definition (every entry finite and below mjMAXVAL; every tee
    and pusher position strictly inside the walls), step by step, over many batches with NaN, +-inf, values just either
    side of the bounds, and negative ones, placed at random."""
    from mjx_pusht.task.invariants import MAX_VAL, WORKSPACE

    rng = np.random.default_rng(2)
    bad = [np.nan, np.inf, -np.inf, MAX_VAL, -MAX_VAL, np.nextafter(MAX_VAL, 0), -np.nextafter(MAX_VAL, 0)]
    edge = [WORKSPACE, -WORKSPACE, np.nextafter(WORKSPACE, 0), -np.nextafter(WORKSPACE, 0), np.nan, 1.0]
    s, n, nq = 10, 8, 5
    for trial in range(300):
        qpos, qvel = rng.normal(size=(s, n, nq)), rng.normal(size=(s, n, nq))
        tee = rng.uniform(-0.39, 0.39, size=(s, n, 3))
        push = rng.uniform(-0.39, 0.39, size=(s, n, 2))
        for arr, values in ((qpos, bad), (qvel, bad), (tee, edge), (push, edge)):
            for _ in range(rng.integers(0, 4)):
                arr[rng.integers(s), rng.integers(n), rng.integers(arr.shape[-1] if arr is not tee else 2)] = \
                    values[rng.integers(len(values))]
        bar, stem = rng.normal(size=(s, n, 3)), rng.normal(size=(s, n, 3))
        t = np.arange(s) + 20
        one_by_one = invariants_init(n, np)
        for j in range(s):
            one_by_one = invariants_update(one_by_one, t[j], 5, tee[j], push[j], qpos[j], qvel[j], bar[j], stem[j])
        at_once = invariants_fold(invariants_init(n, np), t, 5, tee, push, qpos, qvel, bar, stem)
        for key in ("finite", "contained", "gap_max_dev"):
            np.testing.assert_array_equal(at_once[key], one_by_one[key], err_msg=f"{key}, trial {trial}")
        inside = (abs(tee[..., :2]) < WORKSPACE).all(axis=(0, -1)) & (abs(push) < WORKSPACE).all(axis=(0, -1))
        np.testing.assert_array_equal(at_once["contained"], inside, err_msg=f"contained, trial {trial}")


def test_an_all_live_episode_update_equals_the_per_row_selects():
    from mjx_pusht.task.rules import _episode_update_live, _episode_update_select

    rng = np.random.default_rng(3)
    for trial in range(200):
        n = int(rng.integers(1, 6))
        ep = {"done": np.zeros(n, bool), "success": rng.random(n) < 0.3,
              "steps_to_success": rng.choice([-1, 3, 7], n).astype(np.int32),
              "length": rng.integers(0, 50, n).astype(np.int32), "return": rng.random(n) * 10,
              "coverage": rng.random(n), "best_coverage": rng.random(n)}
        reward = rng.choice([0.0, 0.5, 0.95, np.nextafter(0.95, 0), 1.0, np.nan], n)
        k = rng.integers(0, 300) if trial % 2 else rng.integers(0, 300, n)
        for terminate in (True, False):
            fast = _episode_update_live(ep, reward, k, 0.95, terminate)
            ref = _episode_update_select(ep, reward, k, 0.95, terminate)
            for key in ref:
                assert fast[key].dtype == ref[key].dtype and fast[key].shape == ref[key].shape, key
                np.testing.assert_array_equal(fast[key], ref[key], err_msg=key)


def test_the_host_tee_pose_and_ctrl_are_the_array_formulas():
    """The anchored tee pose added in place and the clip as minimum(maximum()) give np.stack's and np.clip's bits."""
    from mjx_pusht.model.layout import QposLayout
    from mjx_pusht.model.scene import SceneSpec, build_model
    from mjx_pusht.task.rules import CTRL_LIMIT, POSITION_GAIN, to_ctrl

    rng = np.random.default_rng(4)
    layout = QposLayout.of(build_model(SceneSpec(variant="gym-pusht")))
    assert layout.anchor is not None
    qpos = rng.normal(size=(10, 7, layout.nq))
    ax, ay = layout.anchor
    yaw = qpos[..., layout.tee[2]]
    c, s = np.cos(yaw), np.sin(yaw)
    want = np.stack([qpos[..., layout.tee[0]] + (ax - (c * ax - s * ay)),
                     qpos[..., layout.tee[1]] + (ay - (s * ax + c * ay)), yaw], axis=-1)
    got = layout.tee_pose(qpos)
    np.testing.assert_array_equal(got, want)
    got[...] = 0  # a new array: the qpos it was read from is untouched
    assert np.array_equal(qpos[..., layout.tee[2]], yaw)
    a, p = rng.normal(scale=2, size=(500, 2)), rng.normal(size=(500, 2))
    a[::7] = np.nan
    a[1::11] = np.inf
    for kind, u in (("velocity", a), ("position", POSITION_GAIN * (a - p))):
        ref = np.clip(np.where(np.isfinite(u), u, 0.0), -CTRL_LIMIT, CTRL_LIMIT)
        np.testing.assert_array_equal(to_ctrl(a, p, kind), ref)


def test_the_drop_ins_host_stack_is_np_stack():
    from mjx_pusht.model.gym_pusht import _stack

    rng = np.random.default_rng(5)
    for shape in ((), (1,), (7,), (3, 8)):
        parts = [rng.normal(size=shape) for _ in range(3)]
        got = _stack(np, parts)
        assert got.dtype == np.float64
        np.testing.assert_array_equal(got, np.stack(parts, axis=-1))
    with np.testing.assert_raises(ValueError):  # parts of different shapes: np.stack's error, never a broadcast
        _stack(np, [np.zeros(2), np.zeros(3)])
