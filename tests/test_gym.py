"""gymnasium: the single env passes gymnasium's checker, and the batched vector env is N single envs, to the bit."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import mjx_pusht  # noqa: E402,F401  (registers mjx_pusht/PushT-v0)
from mjx_pusht.envs.functional import PushTEnv  # noqa: E402
from mjx_pusht.task.episode import Episode  # noqa: E402
from mjx_pusht.task.rules import wrap_angle  # noqa: E402

ENV = "mjx_pusht/PushT-v0"


@pytest.mark.parametrize("obs_type", ["state", "keypoints", "pixels", "pixels_agent_pos"])
def test_single_env_passes_gymnasiums_checker(obs_type):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ENV, obs_type=obs_type, render_mode="rgb_array")
    check_env(env.unwrapped)
    obs, info = env.reset(seed=5)
    assert env.observation_space.contains(obs)
    assert {"coverage", "is_success"} <= set(info)
    frame = env.render()
    assert frame.shape == (512, 512, 3) and frame.dtype == np.uint8
    env.close()


def test_a_seed_is_the_functional_apis_seed():
    env = gym.make(ENV, obs_type="keypoints")
    obs, info = env.reset(seed=1234)
    ref = PushTEnv(backend="cpu").reset([1234])
    np.testing.assert_array_equal(obs, ref.obs["keypoints"][0])
    assert info["coverage"] == ref.metrics["coverage"][0]
    # reset_to_state starts exactly there (tee x, y, yaw, pusher x, y)
    obs, _ = gym.make(ENV).reset(options={"reset_to_state": [0.1, -0.05, 0.3, -0.2, 0.25]})
    np.testing.assert_allclose(obs, [-0.2, 0.25, 0.1, -0.05, 0.3])


def _rollout(envs, steps, rng):
    envs.action_space.seed(0)
    obs, info = envs.reset(seed=7)
    out = [(obs, info["coverage"])]
    for _ in range(steps):
        a = rng.uniform(-1, 1, envs.action_space.shape)
        obs, r, term, trunc, info = envs.step(a)
        out.append((obs, r, term, trunc, info["coverage"], info["is_success"]))
    return out


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_vector_env_equals_gymnasiums_sync_vector_env_through_autoresets(mode):
    kw = dict(max_episode_steps=6, reset_kind="chapter")
    batch = gym.make_vec(ENV, num_envs=8, backend="cpu", autoreset_mode=mode, **kw)
    assert type(batch).__name__ == "PushTVectorEnv"  # one batch, not 8 copies
    copies = gym.make_vec(ENV, num_envs=8, vectorization_mode="sync",
                          vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode(mode)}, **kw)
    assert batch.observation_space == copies.observation_space and batch.action_space == copies.action_space
    a, b = _rollout(batch, 20, np.random.default_rng(3)), _rollout(copies, 20, np.random.default_rng(3))
    ended = 0
    for x, y in zip(a, b):
        for u, v in zip(x, y):
            np.testing.assert_array_equal(u, v)
        if len(x) > 2:
            ended += int(np.sum(x[2] | x[3]))
    assert ended >= 8  # every env went through at least one autoreset (6-step episodes, 20 steps)


def test_vector_env_reports_what_the_functional_api_computes():
    seeds = np.arange(8)
    ref_env = PushTEnv(backend="cpu", episode=Episode(max_steps=300))
    ref = ref_env.reset(seeds)
    envs = gym.make_vec(ENV, num_envs=8, backend="cpu")
    obs, info = envs.reset(seed=[int(s) for s in seeds])
    expected = np.asarray(ref.obs["state"]).copy()
    expected[:, 4] = wrap_angle(expected[:, 4])
    np.testing.assert_array_equal(obs, expected)
    rng = np.random.default_rng(0)
    for _ in range(12):
        act = rng.uniform(-1, 1, (8, 2))
        ref = ref_env.step(ref, act)
        obs, r, term, trunc, info = envs.step(act)
        np.testing.assert_array_equal(r, ref.reward)
        np.testing.assert_array_equal(info["coverage"], ref.metrics["coverage"])
        np.testing.assert_array_equal(info["is_success"], ref.terminated)
        np.testing.assert_array_equal(term, ref.terminated)


def test_disabled_autoreset_resets_only_the_masked_envs():
    envs = gym.make_vec(ENV, num_envs=4, backend="cpu", autoreset_mode="Disabled", render_mode="rgb_array",
                        render_size=64)
    obs0, _ = envs.reset(seed=0)
    for _ in range(3):
        obs, *_ = envs.step(np.full((4, 2), 0.5))
    obs2, info = envs.reset(options={"reset_mask": np.array([True, False, False, True])})
    np.testing.assert_array_equal(obs2[1:3], obs[1:3])
    assert (info["steps"] == [0, 3, 3, 0]).all()
    assert not np.array_equal(obs2[0], obs0[0])  # a new episode: the next seed from env 0's generator
    frames = envs.render()
    assert len(frames) == 4 and frames[0].shape == (64, 64, 3) and not np.array_equal(frames[0], frames[1])
    envs.close()


def test_the_expert_solves_chapter_starts_through_the_vector_env():
    from mjx_pusht.task.controllers import Expert

    envs = gym.make_vec(ENV, num_envs=4, backend="cpu", reset_kind="chapter")
    obs, _ = envs.reset(seed=0)
    expert = Expert()
    cstate = expert.init(np.zeros((4, 2), np.uint32))
    solved = np.zeros(4, bool)
    for k in range(120):
        state = envs.unwrapped._state.obs
        act, cstate = expert.act(cstate, state, k, None)
        obs, r, term, trunc, info = envs.step(np.asarray(act))
        solved |= term
        if solved.all():
            break
    assert solved.all()


def test_without_gymnasium_the_import_error_says_what_to_install():
    code = ("import sys; sys.modules['gymnasium'] = None\n"
            "try:\n    import mjx_pusht.envs.gym\nexcept ImportError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "pip install 'mjx-pusht[gym]'" in out.stdout, out.stdout + out.stderr


def test_bad_arguments_are_one_line_errors():
    with pytest.raises(ValueError, match="unknown obs_type"):
        gym.make(ENV, obs_type="rgb")
    with pytest.raises(ValueError, match="num_envs"):
        gym.make_vec(ENV, num_envs=0, backend="cpu")
    from mjx_pusht.render.pixels import PixelsError

    with pytest.raises(PixelsError, match="mjx-warp"):
        gym.make_vec(ENV, num_envs=2, backend="mjx-jax", obs_type="pixels")


@pytest.mark.slow
@pytest.mark.warp
def test_vector_env_on_mjx_warp_renders_pixels_in_the_batch_and_autoresets():
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    kw = dict(obs_type="pixels_agent_pos", reset_kind="chapter", max_episode_steps=2)
    gpu = gym.make_vec(ENV, num_envs=4, backend="mjx-warp", **kw)
    cpu = gym.make_vec(ENV, num_envs=4, backend="cpu", **kw)
    o1, _ = gpu.reset(seed=3)
    o2, _ = cpu.reset(seed=3)
    for k in range(3):  # through an autoreset (2-step episodes)
        assert o1["pixels"].dtype == np.uint8 and o1["pixels"].shape == (4, 96, 96, 3)
        assert gpu.observation_space.contains(o1)
        assert (o1["pixels"] != o2["pixels"]).any(axis=-1).mean() < 2e-3
        np.testing.assert_allclose(o1["agent_pos"], o2["agent_pos"], atol=1e-4)
        act = np.full((4, 2), 0.4)
        o1, r1, t1, u1, _ = gpu.step(act)
        o2, r2, t2, u2, _ = cpu.step(act)
        np.testing.assert_array_equal(u1, u2)


def test_a_diverged_world_is_flagged_and_warned_about_not_handed_on_quietly():
    env = gym.make(ENV).unwrapped
    env.reset(seed=0)
    # a kick no integrator survives (10 km/s): MuJoCo warns and the world blows up; reset_to_state
    # itself refuses non-finite starts (test_reliability), so the divergence is made in the physics
    env._state.data.datas[0].qvel[:] = 1e4
    with pytest.warns(RuntimeWarning, match="non-finite or left the walls"):
        obs, r, term, trunc, info = env.step(np.zeros(2))
    assert not info["finite"]
    envs = gym.make_vec(ENV, num_envs=2, backend="cpu")
    envs.reset(seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # healthy worlds: no warning
        *_, info = envs.step(np.zeros((2, 2)))
    assert info["finite"].all() and info["contained"].all()


@pytest.mark.parametrize("bad", [np.zeros((2, 3)), np.zeros(6), np.zeros((3, 2, 1)), np.zeros((2, 2))])
def test_a_wrong_shaped_action_is_an_error_never_a_reshape(bad):
    # (2, 3) has the 6 numbers 3 envs need: a reshape would accept it and scramble the worlds
    envs = gym.make_vec(ENV, num_envs=3, backend="cpu")
    envs.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(3, 2\)"):
        envs.step(bad)
    one = gym.make(ENV)
    one.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        one.step(np.zeros(3))


def test_the_vector_api_as_sync_vector_env_offers_it():
    envs = gym.make_vec(ENV, num_envs=3, backend="cpu", max_episode_steps=7, autoreset_mode="same_step")
    copies = gym.make_vec(ENV, num_envs=3, vectorization_mode="sync", max_episode_steps=7)
    # LeRobot reads the episode limit this way; SyncVectorEnv answers with one value per env
    assert envs.call("_max_episode_steps") == copies.call("_max_episode_steps") == (7, 7, 7)
    assert envs.get_attr("obs_type") == copies.get_attr("obs_type") == ("state",) * 3
    assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    assert gym.make_vec(ENV, num_envs=2, backend="cpu", autoreset_mode="SAME_STEP").autoreset_mode.value == "SameStep"
    envs.set_attr("render_size", 64)
    assert envs.get_attr("render_size") == (64, 64, 64)
    with pytest.raises(ValueError, match="one batch"):
        envs.set_attr("render_size", [64, 32, 64])
    with pytest.raises(ValueError, match="unknown autoreset_mode"):
        gym.make_vec(ENV, num_envs=2, backend="cpu", autoreset_mode="sometimes")


def test_call_render_gives_one_frame_per_env_as_sync_vector_env_does():
    """gymnasium's `call` calls `name` on each sub-environment: render is one frame each. The batch env used to
    hand its whole batch of frames to every env (3 envs: three (3, H, W, 3) arrays)."""
    kw = dict(render_mode="rgb_array", render_size=64)
    envs = gym.make_vec(ENV, num_envs=3, backend="cpu", **kw)
    copies = gym.vector.SyncVectorEnv([lambda: gym.make(ENV, **kw) for _ in range(3)])
    envs.reset(seed=[4, 5, 6])
    copies.reset(seed=[4, 5, 6])
    ours, theirs = envs.call("render"), copies.call("render")
    assert isinstance(ours, tuple) and len(ours) == len(theirs) == 3
    for a, b, c in zip(ours, theirs, envs.render()):
        assert a.shape == b.shape == (64, 64, 3)
        np.testing.assert_array_equal(a, c)  # env i's own frame, in env order
    assert not np.array_equal(ours[0], ours[1])  # different seeds, different pictures
    quiet, quiet_copies = gym.make_vec(ENV, num_envs=2, backend="cpu"), gym.vector.SyncVectorEnv([lambda: gym.make(ENV)] * 2)
    quiet.reset(seed=0)
    quiet_copies.reset(seed=0)
    assert quiet.call("render") == quiet_copies.call("render") == (None, None)  # no render_mode: None per env


@pytest.fixture(scope="module")
def warp_vector_pair():
    """Two 4-env MJX-Warp vector envs, built (and their step compiled) once for the three non-finite values below:
    each case starts both from reset(seed=7), so it sees the fresh batch it would see in envs of its own."""
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    return (gym.make_vec(ENV, num_envs=4, backend="mjx-warp", array_type="jax"),
            gym.make_vec(ENV, num_envs=4, backend="mjx-warp", array_type="jax"))


@pytest.mark.slow
@pytest.mark.warp
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_device_batchs_non_finite_action_is_named_at_the_next_read_and_its_row_held_still(bad, warp_vector_pair):
    """On MJX the vector env reads the batch on the host every few steps, not each step: a non-finite action is
    checked on the device, its row gets action 0 (the pusher holds still: compared with a zero action), and the
    next read raises one line naming the row and the step."""
    import jax.numpy as jnp

    envs, ref = warp_vector_pair
    envs.reset(seed=7)
    ref.reset(seed=7)
    a = jnp.full((4, 2), 0.3)
    envs.step(a)
    ref.step(a)
    held = a.at[2, 1].set(bad)
    with pytest.raises(ValueError, match=r"at step 1 since reset, row\(s\) 2 \(of 4\)") as e:
        for _ in range(16):  # the next read comes within depth // 2 steps
            o1, *_ = envs.step(held)
            o2, *_ = ref.step(a.at[2].set(0.0))
            np.testing.assert_array_equal(np.asarray(o1), np.asarray(o2))  # row 2 held still, the others as asked
    assert "\n" not in str(e.value)
