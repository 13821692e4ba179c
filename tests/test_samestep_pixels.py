"""Same-step autoreset with images: one render a step, the new episodes' first images from the start pool.

A row whose episode ends in a step shows two images in it: the last one of the ended episode
(`info["final_obs"]`) and the first one of its new episode (`obs`). Both must be the images of those
states: here each is checked against the same states rendered independently, row by row, by a
renderer of its own (`PushTEnv.images`, from the states the infos report), and against the step
that renders every world twice (`image_pool=False`), to the byte.
"""

from __future__ import annotations

import numpy as np
import pytest

SIZE = 24  # small images: the renders run on Warp's CPU device here


@pytest.fixture(scope="module")
def reference():
    """Images of (pusher x, y, tee x, y, yaw) states, from a renderer of three worlds of its own."""
    from mjx_pusht.backends.warp import warp_available
    from mjx_pusht.envs.functional import PushTEnv

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    env = PushTEnv(backend="mjx-warp", pixels=SIZE, reset_kind="chapter")
    draw = env.images(3)
    return lambda states: np.asarray(draw(np.asarray(states, np.float32)))


def _states(info):
    return np.concatenate([np.asarray(info["pos_agent"]), np.asarray(info["block_pose"])], axis=-1)


@pytest.mark.slow
@pytest.mark.warp
def test_same_step_images_are_those_of_the_ended_and_the_new_episodes(reference):
    """The pixel vector env in same_step mode through many autoresets (episodes of 3 steps, queues of 2,
    refilled as it goes): every obs image and every final_obs image is its state's image."""
    import gymnasium as gym

    import mjx_pusht  # noqa: F401

    env = gym.make_vec("mjx_pusht/PushT-v0", num_envs=3, backend="mjx-warp", obs_type="pixels_agent_pos",
                       observation_size=SIZE, autoreset_mode="same_step", array_type="numpy", depth=2,
                       max_episode_steps=3, reset_kind="chapter")
    assert env.unwrapped._ar._pooled_images()
    obs, info = env.reset(seed=7)
    np.testing.assert_array_equal(obs["pixels"], reference(_states(info)))
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(8):
        obs, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, (3, 2)))
        np.testing.assert_array_equal(obs["pixels"], reference(_states(info)))
        ended = terminated | truncated
        if ended.any():
            final = info["final_obs"]["pixels"]
            np.testing.assert_array_equal(final[ended], reference(_states(info["final_info"]))[ended])
            # the new episode's first image is not the old one's last (the T and the pusher moved)
            assert (final[ended] != obs["pixels"][ended]).any()
        ends += int(ended.sum())
    assert ends >= 6  # every row ended twice at least: images from refilled queue slots too
    assert env.unwrapped._ar._jitted[3]._cache_size() == 1  # the pool's refills compiled no second step
    env.close()


@pytest.mark.slow
@pytest.mark.warp
@pytest.mark.parametrize("goal", ["fixed", "random"])
def test_pooled_first_images_equal_the_second_render_when_rows_end_every_step(reference, goal):
    """AutoReset on its own, every row ending every step, past its queue's depth (slots reused, no refill):
    the images equal the twice-rendering step's and each state's own image (with random goals, the pool's image
    draws the target at its start's goal, as the step's own render of the new episode does)."""
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.envs.wrappers import AutoReset
    from mjx_pusht.task.episode import Episode

    env = PushTEnv(backend="mjx-warp", pixels=SIZE, reset_kind="chapter", episode=Episode(max_steps=1), goal=goal)
    pooled = AutoReset(env, "same_step", depth=2, final_pixels=True)
    twice = AutoReset(env, "same_step", depth=2, final_pixels=True, image_pool=False)
    a, b = pooled.reset(np.arange(3)), twice.reset(np.arange(3))
    assert "pool_pixels" in a.info and "pool_pixels" not in b.info
    rng = np.random.default_rng(1)
    for i in range(5):
        act = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        images = a.info["pool_pixels"]
        a, b = pooled.step(a, act), twice.step(b, act)
        assert a.info["pool_pixels"] is images  # handed through, not copied by the step
        assert np.asarray(a.truncated).all()
        for key in ("obs", "final"):
            pa = np.asarray((a.obs if key == "obs" else a.info["final"]["obs"])["pixels"])
            pb = np.asarray((b.obs if key == "obs" else b.info["final"]["obs"])["pixels"])
            np.testing.assert_array_equal(pa, pb)
            state = np.asarray((a.obs if key == "obs" else a.info["final"]["obs"])["state"])
            if goal == "fixed":  # the reference draws the scene's target
                np.testing.assert_array_equal(pa, reference(state))
    assert np.asarray(a.info["used"]).min() == 5  # five episodes a row from a queue of two: slots reused
