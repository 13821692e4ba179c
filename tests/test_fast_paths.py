"""The CPU env's fast paths give the array code's bits: the invariants folded over a control step's physics
steps at once, and the coverage of a few host poses in plain floats."""

from __future__ import annotations

import numpy as np

from mjx_pusht.task.invariants import invariants_fold, invariants_init, invariants_update
from mjx_pusht.task.rules import T_REACH, _coverage, _coverage_few


def test_folding_the_physics_steps_at_once_equals_folding_them_one_by_one():
    rng = np.random.default_rng(0)
    s, n, nq = 10, 6, 5
    qpos, qvel = rng.normal(size=(s, n, nq)), rng.normal(size=(s, n, nq))
    bar, stem = rng.normal(size=(s, n, 3)), rng.normal(size=(s, n, 3))
    tee = rng.normal(scale=0.3, size=(s, n, 3))
    qpos[3, 1, 2] = np.nan  # a world that diverges mid-step
    qvel[7, 2, 0] = 1e11  # beyond mjMAXVAL
    bar[5, 3, 1] = np.nan  # a NaN gap propagates into the peak
    tee[2, 4, 0] = 0.5  # outside the walls
    k = np.array([0, 0, 1, 2, 5, 0])  # rows at different control steps: the settle step falls in some of them
    for settle in (0, 7, 12, 23):
        t = k[None] * s + np.arange(s)[:, None]
        one_by_one = invariants_init(n, np)
        for j in range(s):
            one_by_one = invariants_update(one_by_one, t[j], settle, tee[j], qpos[j], qvel[j], bar[j], stem[j])
        at_once = invariants_fold(invariants_init(n, np), t, settle, tee, qpos, qvel, bar, stem)
        for key in one_by_one:
            np.testing.assert_array_equal(at_once[key], one_by_one[key], err_msg=key)
    scalar_k = invariants_fold(invariants_init(n, np), 3 * s + np.arange(s), 35, tee, qpos, qvel, bar, stem)
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
    target = np.array([0.05, -0.02, 0.7])  # another target pose, given once for all rows and row by row
    ref = _coverage(poses, np.broadcast_to(target, poses.shape))
    np.testing.assert_array_equal(np.concatenate([_coverage_few(poses[i : i + 1], target) for i in range(n)]), ref)
    np.testing.assert_array_equal(_coverage_few(poses[:3], np.broadcast_to(target, (3, 3))), ref[:3])
