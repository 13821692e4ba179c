"""Random goals (gym-pusht#17): a goal pose per episode from its seed, inside the walls with room to push, observed
beside the T, and reward and success scored against it (checked here with `coverage_one` in the goal's frame, an
independent computation: coverage is unchanged by moving both Ts together)."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.errors import ConfigError
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.goals import goal_poses, in_goal_frame, to_goal_frame
from mjx_pusht.task.rules import WORKSPACE_HALF, coverage_one, keypoints
from mjx_pusht.task.tasks import get

ROOM = 2 * 0.015 + 0.01  # a pusher's width and a centimetre, between the goal T and any wall


def test_a_seeds_goal_is_its_own_generators_draw_inside_the_walls_with_room_to_push():
    seeds = np.arange(3000)
    g = goal_poses(seeds, "chapter")
    rng = np.random.default_rng([17, 0x60A1])
    half = WORKSPACE_HALF - np.hypot(0.015, 0.105) - ROOM
    want = [rng.uniform(-half, half), rng.uniform(-half, half), rng.uniform(-np.pi, np.pi)]
    np.testing.assert_allclose(g[17], want, rtol=0, atol=1e-15)
    corners = keypoints(g).reshape(-1, 8, 2)
    assert np.abs(corners).max() <= WORKSPACE_HALF - ROOM + 1e-12
    assert g[:, 0].min() < -0.2 and g[:, 0].max() > 0.2 and g[:, 1].min() < -0.2 and g[:, 1].max() > 0.2  # spread out
    lo, hi = frame.WALL_INNER_PX  # gym-pusht's walls, in its pixels (1 mm each): a square turned by pi/4 in the world
    px = frame.to_px(keypoints(goal_poses(seeds, "gym-pusht")).reshape(-1, 2))
    assert lo + ROOM / frame.PX - 1e-6 <= px.min() and px.max() <= hi - ROOM / frame.PX + 1e-6
    assert px.min() < lo + ROOM / frame.PX + 20 and px.max() > hi - ROOM / frame.PX - 20  # reaching the bounds


def goal_episodes(task: str, seeds, max_steps: int):
    """The task's expert, seeing the T from the goal's frame, on random goals (MuJoCo C): the final state, and every
    step's reward checked against `coverage_one` of the T in its goal's frame. Returns (state, reached 0.95)."""
    t = get(task)
    env = PushTEnv.for_task(task, max_steps=max_steps, goal="random")
    s = env.reset(seeds)
    fixed = PushTEnv.for_task(task).reset(seeds)
    np.testing.assert_array_equal(s.obs["state"], fixed.obs["state"])  # a seed starts where it always did
    np.testing.assert_array_equal(s.obs["goal"], goal_poses(seeds, t.variant))
    assert "goal" not in fixed.obs and "goal" not in fixed.carry  # a fixed goal carries nothing
    ctrl = in_goal_frame(t.controller("expert"))
    carry = ctrl.init(s.key)
    reached = np.zeros(len(seeds), bool)
    while not s.carry["ep"]["done"].all():
        action, carry = ctrl.act(carry, s.obs, s.step, s.key)
        live = ~s.carry["ep"]["done"]
        s = env.step(s, action)
        for i in np.flatnonzero(live):
            mine = coverage_one(*to_goal_frame(s.obs["state"][i, 2:5], s.obs["goal"][i]).tolist())
            assert abs(s.reward[i] - mine) < 1e-12
            reached[i] |= mine >= 0.95
    np.testing.assert_array_equal(s.metrics["success"], reached)
    return s, reached


@pytest.mark.parametrize("task", ["gym-pusht", "chapter"])
def test_reward_follows_the_goal_step_by_step(task):
    s, _ = goal_episodes(task, np.arange(4), 25)
    assert s.reward.max() > 0.05  # the check saw Ts overlapping their goals, not only zeros


@pytest.mark.slow  # 16 episodes of the experts (about 10 s on 2 cores)
@pytest.mark.parametrize("task", ["gym-pusht", "chapter"])
def test_the_expert_follows_a_random_goal_and_succeeds_by_it(task):
    _, reached = goal_episodes(task, np.arange(8), 300)
    assert reached.sum() >= 6


def test_goal_options_are_checked_in_one_line():
    with pytest.raises(ConfigError, match="unknown goal 'moving'; choose from fixed, random"):
        PushTEnv(goal="moving")
    with pytest.raises(ConfigError, match="random goals are not drawn in pixel observations yet"):
        PushTEnv(goal="random", pixels=32)


@pytest.mark.slow  # compiles MJX-JAX's and MJX-Warp's steps (about 30 s on 2 cores)
def test_a_seed_draws_the_same_goal_on_every_backend_and_each_scores_against_it():
    rewards = {}
    for b in ("cpu", "mjx-jax", "mjx-warp"):
        env = PushTEnv.for_task("gym-pusht", backend=b, goal="random")
        s = env.reset(np.arange(4))
        for _ in range(2):  # push toward the T's centre
            s = env.step(s, np.asarray(s.obs["state"][:, 2:4]))
        goal, final = np.asarray(s.obs["goal"], np.float64), np.asarray(s.carry["final"], np.float64)
        np.testing.assert_array_equal(goal, goal_poses(np.arange(4), "gym-pusht").astype(s.obs["goal"].dtype))
        mine = [coverage_one(*to_goal_frame(final[i], goal[i]).tolist()) for i in range(4)]
        np.testing.assert_allclose(np.asarray(s.reward), mine, atol=1e-6)
        rewards[b] = np.asarray(s.reward)
    assert rewards["cpu"].max() > 0.05  # the goals' Ts overlap the pushed ones: the check saw coverage
