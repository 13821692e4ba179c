"""The functional environment: shapes, termination, truncation, and the same control step as the rollouts."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.controllers import (
    Expert,
    seed_key,
)
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.rules import keypoints


def test_env_shapes_dtypes_and_keypoints():
    env = PushTEnv(backend="cpu", episode=Episode(max_steps=5))
    s = env.reset(np.arange(3))
    assert s.obs["state"].shape == (3, 5) and s.obs["keypoints"].shape == (3, 16)
    assert s.obs["state"].dtype == np.float64 and s.step.dtype == np.int32
    s = env.step(s, np.zeros((3, 2)))
    assert s.reward.shape == (3,) and s.terminated.dtype == bool and s.truncated.dtype == bool
    # keypoints: the bar's top-left corner, rotated and placed by hand
    x, y, yaw = s.obs["state"][0, 2:]
    c, sn = np.cos(yaw), np.sin(yaw)
    assert s.obs["keypoints"][0, :2] == pytest.approx([x + c * -0.06 - sn * 0.015, y + sn * -0.06 + c * 0.015])
    assert keypoints(np.zeros(3))[8:10].tolist() == [0.015, -0.105]  # the stem's bottom-right corner


def test_pixel_frame_puts_the_walls_on_the_image_edges_and_round_trips():
    from mjx_pusht.task.rules import from_pixels, to_pixels

    corners = np.array([[-0.39, 0.39], [0.39, -0.39], [0.0, 0.0]])
    np.testing.assert_allclose(to_pixels(corners), [[0, 0], [512, 512], [256, 256]])
    xy = np.random.default_rng(0).uniform(-0.39, 0.39, (10, 2))
    np.testing.assert_allclose(from_pixels(to_pixels(xy, 96), 96), xy, atol=1e-15)


def test_an_episode_that_starts_covered_terminates_at_once_and_its_first_step_reports_the_success():
    env = PushTEnv(backend="cpu")
    s = env.reset_to([[0.0, 0.0, 0.0, 0.2, 0.2], [0.1, 0.1, 0.0, 0.2, -0.2]])
    assert s.terminated.tolist() == [True, False]
    s2 = env.step(s, np.full((2, 2), 0.5))
    # the step that reports the end carries the reward of the covered start (coverage 1 on the goal)
    assert s2.terminated[0] and s2.reward[0] == 1.0 and s2.step[0] == 1
    assert s2.step[1] == 1
    np.testing.assert_array_equal(s2.obs["state"][0], s.obs["state"][0])  # an ended episode holds still
    s3 = env.step(s2, np.full((2, 2), 0.5))  # after that it earns nothing until it is reset
    assert s3.reward[0] == 0.0 and s3.step[0] == 1 and s3.terminated[0]


def test_terminated_episodes_stop_accumulating_reward():
    env = PushTEnv(backend="cpu", reset_kind="chapter")
    s = env.reset(np.array([3]))
    ctrl, key = Expert(), seed_key([3])
    mode = ctrl.init(key)
    total = 0.0
    for k in range(300):
        a, mode = ctrl.act(mode, s.obs, k, key)
        s = env.step(s, a)
        total += float(s.reward[0])
        if s.terminated[0]:
            break
    assert s.terminated[0] and s.metrics["success"][0] and s.metrics["return"][0] == pytest.approx(total)
    done_return, done_step = s.metrics["return"][0], s.step[0]
    for _ in range(3):
        s = env.step(s, np.ones((1, 2)))
        assert s.reward[0] == 0.0
    assert s.metrics["return"][0] == done_return and s.step[0] == done_step


def test_truncation_after_max_steps():
    env = PushTEnv(backend="cpu", episode=Episode(max_steps=3))
    s = env.reset(np.arange(2))
    for k in range(3):
        assert not s.truncated.any()
        s = env.step(s, np.zeros((2, 2)))
    assert s.truncated.all() and not s.terminated.any() and (s.step == 3).all()


def test_env_steps_match_the_batched_rollout():
    """env.step with the expert's actions is the rollout the eval runs, to the bit (both on MuJoCo C)."""
    seeds = np.arange(3)
    r = run_cpu(Scenario(reset="task", controller=Expert(), episode=Episode(max_steps=25)), seeds)
    env = PushTEnv(backend="cpu", episode=Episode(max_steps=25))
    s = env.reset(seeds)
    ctrl, key = Expert(), seed_key(seeds)
    mode = ctrl.init(key)
    for k in range(25):
        a, mode = ctrl.act(mode, s.obs, k, key)
        s = env.step(s, a)
    np.testing.assert_array_equal(s.obs["state"][:, 2:], r.final)
    np.testing.assert_array_equal(s.metrics["return"], r.episode["return"])


def test_velocity_actions_are_clipped_and_position_actions_are_tracked():
    env = PushTEnv(backend="cpu", reset_kind="chapter", episode=Episode(max_steps=50))
    s = env.step(env.reset(np.array([0])), np.array([[5.0, 0.0]]))
    one = env.step(env.reset(np.array([0])), np.array([[1.0, 0.0]]))
    np.testing.assert_array_equal(s.obs["state"], one.obs["state"])  # clipped to the ctrlrange
    # the servo from rest: m dv/dt = kv (u - v) - b v, with m 0.2, kv 20, b 0.5: first order, tau = m / (kv + b)
    v_inf, tau = 20 / 20.5, 0.2 / 20.5
    assert s.obs["state"][0, 0] == pytest.approx(v_inf * (0.1 - tau * (1 - np.exp(-0.1 / tau))), abs=5e-4)
    pos = PushTEnv(backend="cpu", reset_kind="chapter", action_type="position", episode=Episode(max_steps=50))
    s = pos.reset(np.array([0]))
    goal = np.array([[-0.2, -0.3]])
    for _ in range(15):
        s = pos.step(s, goal)
    assert np.hypot(*(s.obs["state"][0, :2] - goal[0])) < 0.005


# --- one rollout: the chapter's schedule is one controller ------------------------------------


@pytest.mark.warp
@pytest.mark.slow
def test_an_undersized_warp_buffer_is_caught_loudly_never_handed_on_as_physics():
    from mjx_pusht.backends.warp import BufferOverflow

    # one contact and four rows per world cannot hold the pusher pressing into the T (a cylinder-box
    # contact is up to 4 points and 4 rows each): drive the pusher up into the T until something is dropped
    env = PushTEnv(backend="mjx-warp", reset_kind="chapter", contacts_per_world=1, rows_per_world=4)
    state = env.reset(np.arange(4))
    with pytest.raises(BufferOverflow, match="dropped"):
        for _ in range(30):
            state = env.check(env.step(state, np.tile([0.0, 1.0], (4, 1))))
    # the default sizes (the sweep's) hold the same push without a drop
    env = PushTEnv(backend="mjx-warp", reset_kind="chapter")
    state = env.reset(np.arange(4))
    for _ in range(30):
        state = env.check(env.step(state, np.tile([0.0, 1.0], (4, 1))))
    assert not np.asarray(state.dropped).any()


def test_an_unknown_warp_graph_mode_is_one_line():
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown graph mode 'BOGUS'; choose from NONE, JAX, WARP, WARP_STAGED"):
        PushTEnv(backend="mjx-warp", graph_mode="BOGUS")
