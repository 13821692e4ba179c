"""The easy variant (gym-pusht#18's "trivial variant", to debug a policy on): the `easy` starts, the tee a few cm and
degrees off the target with the pusher beside it, inside either scene's walls, never covered, and solved by each
task's expert in a few dozen control steps."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.reset import PUSHER_RADIUS, start_poses
from mjx_pusht.task.rules import WORKSPACE_HALF, coverage_np, keypoints
from mjx_pusht.task.tasks import TASKS, get

MANY = np.arange(20_000)


def test_each_seed_draws_its_easy_start_from_its_own_generator_in_order():
    for seed in (0, 7, 2**40 + 3):
        rng = np.random.default_rng(seed)
        dist, heading, yaw, side = (rng.uniform(0.015, 0.04), rng.uniform(-np.pi, np.pi), rng.uniform(-0.3, 0.3),
                                    rng.uniform(-np.pi, np.pi))
        x, y = dist * np.cos(heading), dist * np.sin(heading)
        reach = np.hypot(0.015, 0.105) + 0.015 + 0.01  # the T's farthest point, the pusher's radius, 1 cm clear
        want = [x, y, yaw, x + reach * np.cos(side), y + reach * np.sin(side)]
        np.testing.assert_allclose(start_poses([seed], reset="easy")[0], want, rtol=0, atol=1e-15)


def test_easy_starts_lie_inside_both_scenes_walls_and_none_is_covered():
    s = start_poses(MANY, reset="easy")
    corners = keypoints(s[:, 0:3]).reshape(-1, 8, 2)
    # the chapter's scene: walls' inner faces at +-0.39 m
    assert np.abs(corners).max() < WORKSPACE_HALF and np.abs(s[:, 3:5]).max() + PUSHER_RADIUS < WORKSPACE_HALF
    # gym-pusht's scene: its walls in its pixels (the world frame there is its goal's, turned by pi/4)
    lo, hi = frame.WALL_INNER_PX
    px = frame.to_px(corners.reshape(-1, 2))
    agent = frame.to_px(s[:, 3:5])
    assert lo < px.min() and px.max() < hi
    assert lo + frame.AGENT_RADIUS_PX < agent.min() and agent.max() < hi - frame.AGENT_RADIUS_PX
    cov = coverage_np(s[:, 0:3])
    assert cov.max() < 0.8  # never a start on the goal: there is always a push to make
    assert cov.min() > 0.1  # and always near it (a 4 cm offset and 0.3 rad still overlap by 15% at least)


@pytest.mark.parametrize("task, reset", [("gym-pusht-easy", None), ("chapter", "easy")])
def test_each_tasks_expert_solves_the_easy_starts_in_a_few_dozen_steps(task, reset):
    from mjx_pusht.envs.functional import PushTEnv

    t = get(task)
    env = PushTEnv(reset_kind=t.check_reset(reset), action_type=t.action_type, episode=t.episode(max_steps=100),
                   scene=t.scene())
    ctrl = t.controller("expert")
    s = env.reset(np.arange(16))
    carry = ctrl.init(s.key)
    while not s.carry["ep"]["done"].all():
        action, carry = ctrl.act(carry, s.obs, s.step, s.key)
        s = env.step(s, action)
    m = s.metrics
    assert m["success"].sum() >= 15
    assert np.median(m["steps_to_success"][m["success"]]) <= 60  # the full task's median is 100-115


def test_the_easy_variant_is_taken_by_name_by_the_envs():
    import gymnasium as gym

    import mjx_pusht  # noqa: F401
    from mjx_pusht.envs.functional import PushTEnv

    want = start_poses([5, 6], reset="easy")  # tee x, y, yaw, pusher x, y
    state = PushTEnv.for_task("gym-pusht-easy").reset([5, 6]).obs["state"]  # pusher x, y, tee x, y, yaw
    np.testing.assert_array_equal(state, want[:, [3, 4, 0, 1, 2]])
    single = gym.make("mjx_pusht/PushT-v0", reset_kind="easy").unwrapped
    np.testing.assert_allclose(single.reset(seed=5)[0], want[0, [3, 4, 0, 1, 2]], rtol=0, atol=1e-12)
    drop_in = gym.make("mjx_pusht/PushT-gym-pusht-v0", reset_kind="easy").unwrapped
    _, info = drop_in.reset(seed=6)
    origin, angle = frame.pose_to_px(want[1:2, 0:3])
    np.testing.assert_allclose(info["block_pose"], [*origin[0], angle[0]], rtol=0, atol=1e-9)
    assert TASKS["gym-pusht-easy"].variant == "gym-pusht" and "easy" in TASKS["chapter"].resets
