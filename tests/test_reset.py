"""The reset contract: seed -> start pose, each seed its own generator, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.task.reset import CLEARANCE, PUSHER_RADIUS, start_poses


@pytest.mark.parametrize("reset", ["chapter", "task"])
def test_start_poses_are_each_seeds_own_generator_bit_for_bit(reset):
    from mjx_pusht.task.reset import start_state

    rng = np.random.default_rng(2026)
    seeds = np.concatenate([[0, 1, 2**32 - 1, 2**32, 2**32 + 1, 2**63 - 1], rng.integers(0, 2**63 - 1, 300),
                            rng.integers(0, 2**32, 100)])
    batch = start_poses(seeds, reset=reset)
    one_by_one = np.array([start_state(int(s), reset) for s in seeds])[:, : batch.shape[1]]
    np.testing.assert_array_equal(batch, one_by_one)


def test_reset_is_per_seed_and_task_starts_are_clear():
    a = start_poses(np.array([5, 9, 11]), reset="task")
    b = start_poses(np.array([9]), reset="task")
    np.testing.assert_array_equal(a[1], b[0])
    many = start_poses(np.arange(500), reset="task")
    assert np.abs(many[:, :2]).max() < 0.39 - 0.106  # every point of the T inside the walls
    assert np.abs(many[:, 3:5]).max() < 0.39 - PUSHER_RADIUS
    # independent check that the pusher is clear of the T: sample the T's area densely
    for tee, pusher in zip(many[:50, :3], many[:50, 3:5]):
        u, v = np.meshgrid(np.linspace(-0.06, 0.06, 49), np.linspace(-0.015, 0.015, 13))
        pts = [np.column_stack([u.ravel(), v.ravel()])]
        u, v = np.meshgrid(np.linspace(-0.015, 0.015, 13), np.linspace(-0.105, -0.015, 37))
        pts.append(np.column_stack([u.ravel(), v.ravel()]))
        local = np.concatenate(pts)
        c, s = np.cos(tee[2]), np.sin(tee[2])
        world = local @ np.array([[c, s], [-s, c]]) + tee[:2]
        assert np.hypot(*(world - pusher).T).min() > PUSHER_RADIUS + CLEARANCE - 1e-3
    assert np.abs(many[:, 2]).max() > 3.0  # any yaw
