"""The envs under the clients people run them with: SB3, torchrl, gymnasium's checkers and vector envs.

Each env owns its rendering (closing one never changes another's images, and a closed env renders
again), gymnasium's TimeLimit holds the episode limit, an async vector env under `fork` works or
refuses in one line, and a start on the goal is rewarded as the success it reports.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import mjx_pusht  # noqa: E402,F401  (registers the ids)

V0, DROP_IN = "mjx_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"
IDS = [V0, DROP_IN]
OBS = {V0: ["state", "keypoints", "pixels", "pixels_agent_pos"],
       DROP_IN: ["state", "environment_state_agent_pos", "pixels", "pixels_agent_pos"]}
ON_GOAL_V0 = [0.0, 0.0, 0.0, 0.25, 0.25]  # the tee on the target, the pusher well away
# gym-pusht's reset_to_state places the block's origin at position + (0, 45) - R(angle)(0, 45): on the goal
ON_GOAL_PX = [100.0, 100.0, 256 - 45 * np.sin(np.pi / 4), 256 - 45 + 45 * np.cos(np.pi / 4), np.pi / 4]


def pixels_of(obs):
    return obs["pixels"] if isinstance(obs, dict) else obs


def vec(env_id, n=2, **kw):
    return gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", backend="cpu", **kw)


# -- rendering each env owns ------------------------------------------------------------------------
@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("kind", ["single", "vector"])
def test_closing_one_pixel_env_leaves_anothers_images_unchanged(env_id, kind):
    make = (lambda: gym.make(env_id, obs_type="pixels")) if kind == "single" else (lambda: vec(env_id, obs_type="pixels"))
    survivor = make()
    before = pixels_of(survivor.reset(seed=3)[0]).copy()
    other = make()
    other.reset(seed=1)
    pixels_of(survivor.reset(seed=3)[0])  # the survivor's context is the current one when the other closes
    other.close()
    for _ in range(3):  # the bug made every reset's image differ: garbage, with no error
        np.testing.assert_array_equal(pixels_of(survivor.reset(seed=3)[0]), before)
    survivor.close()


def test_pixel_envs_made_closed_and_made_again_in_any_order_draw_the_same_images():
    def image(env):
        return pixels_of(env.reset(seed=7)[0]).copy()

    first = {i: image(gym.make(i, obs_type="pixels")) for i in IDS}
    envs = [gym.make(V0, obs_type="pixels"), vec(DROP_IN, obs_type="pixels"), gym.make(DROP_IN, obs_type="pixels"),
            vec(V0, obs_type="pixels")]
    for e in envs:
        e.reset(seed=0)
    for k in (2, 0, 3):  # close some, in no particular order, and make one again
        envs[k].close()
    envs.append(gym.make(V0, obs_type="pixels"))
    np.testing.assert_array_equal(image(envs[-1]), first[V0])
    np.testing.assert_array_equal(image(envs[1])[0], first[DROP_IN])
    envs[0].reset(seed=7)  # reset after close: rendering is made again on demand
    np.testing.assert_array_equal(image(envs[0]), first[V0])


@pytest.mark.slow
@pytest.mark.parametrize("env_id", IDS)
def test_sb3_check_env_with_rendering_on_every_obs_type(env_id):
    from stable_baselines3.common.env_checker import check_env

    for obs_type in OBS[env_id]:
        env = gym.make(env_id, obs_type=obs_type, render_mode="rgb_array")
        check_env(env)  # closes the env, then resets and renders it again
        env.reset(seed=0)
        assert env.render().shape[2] == 3


def test_gymnasiums_check_env_on_pixels_after_other_pixel_envs_were_made_and_closed():
    from gymnasium.utils.env_checker import check_env

    for env_id in IDS:
        for _ in range(2):
            e = gym.make(env_id, obs_type="pixels_agent_pos", render_mode="rgb_array")
            e.reset(seed=1)
            e.render()
            e.close()
    keep = gym.make(V0, obs_type="pixels")
    keep.reset(seed=0)
    for env_id in IDS:
        check_env(gym.make(env_id, obs_type="pixels", render_mode="rgb_array").unwrapped)  # determinism included


def test_torchrl_checks_the_env_specs():
    torchrl_envs = pytest.importorskip("torchrl.envs")
    from torchrl.envs.utils import check_env_specs

    for env_id in IDS:
        check_env_specs(torchrl_envs.GymEnv(env_id))


# -- async vector envs under fork --------------------------------------------------------------------
def _run(code: str, timeout: float = 60):
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.slow
@pytest.mark.parametrize("env_id", IDS)
def test_async_vector_env_with_pixels_under_fork_completes_within_60_s(env_id):
    r = _run(f"""
        import multiprocessing, sys, gymnasium as gym, mjx_pusht
        assert multiprocessing.get_start_method() == "fork"
        envs = gym.make_vec({env_id!r}, 2, vectorization_mode="async", obs_type="pixels_agent_pos")
        obs, _ = envs.reset(seed=0)
        for _ in range(3):
            obs, *_ = envs.step(envs.action_space.sample())
        envs.close()
        print(obs["pixels"].shape, "jax" in sys.modules)
    """)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["(2,", "96,", "96,", "3)", "False"]  # and the parent never needed JAX


def test_async_fork_after_the_parent_rendered_refuses_in_one_line_naming_forkserver():
    r = _run(f"""
        import gymnasium as gym, mjx_pusht
        gym.make({V0!r}, obs_type="pixels").reset(seed=0)  # EGL initialised here, in the parent
        envs = gym.make_vec({V0!r}, 2, vectorization_mode="async", obs_type="pixels")
        try:
            envs.reset(seed=0)
        except mjx_pusht.errors.MjxPushtError as e:
            print("refused:", e)
        envs.close(terminate=True)
    """)
    assert r.returncode == 0, r.stderr
    line = r.stdout.strip()
    assert line.startswith("refused:") and "forkserver" in line and "\n" not in line


# -- episode limits and the goal start -----------------------------------------------------------------
@pytest.mark.parametrize("env_id", IDS)
def test_the_episode_limit_is_in_the_spec_and_max_episode_steps_replaces_it(env_id):
    assert gym.make(env_id).spec.max_episode_steps == 300
    assert gym.spec(env_id).max_episode_steps == 300
    hold = (lambda o: np.zeros(2)) if env_id == V0 else (lambda o: np.asarray(o[:2]))  # velocity 0 / target = agent
    for limit in (3, 500):
        env = gym.make(env_id, max_episode_steps=limit)
        o, _ = env.reset(seed=2)
        steps, truncated = 0, False
        while not truncated:
            o, _, terminated, truncated, _ = env.step(hold(o))
            steps += 1
            assert not terminated
        assert steps == limit  # gymnasium's TimeLimit, not a limit inside the env
    envs = vec(env_id, max_episode_steps=4)  # the vector entry point takes the limit as its own
    assert envs.call("_max_episode_steps") == (4, 4)
    o, _ = envs.reset(seed=2)
    flags = []
    for _ in range(4):
        o, _, _, truncated, _ = envs.step(np.zeros((2, 2)) if env_id == V0 else o[:, :2])
        flags.append(bool(truncated.all()))
    assert flags == [False, False, False, True]
    with pytest.raises(ValueError, match="max_episode_steps"):
        vec(env_id, max_episode_steps=0)


def test_a_start_on_the_goal_reports_success_and_its_first_step_is_rewarded_as_one():
    env = gym.make(V0)
    _, info = env.reset(options={"reset_to_state": ON_GOAL_V0})
    assert info["is_success"] and info["coverage"] == 1.0
    _, reward, terminated, truncated, info = env.step(np.zeros(2))
    assert terminated and not truncated and reward == info["coverage"] == 1.0  # PushT-v0's reward is the coverage


def test_the_drop_ins_goal_start_is_rewarded_as_gym_pusht_rewards_it():
    gym_pusht = pytest.importorskip("gym_pusht")  # noqa: F841
    results = []
    for env_id in ("gym_pusht/PushT-v0", DROP_IN):
        env = gym.make(env_id)
        o, _ = env.reset(options={"reset_to_state": ON_GOAL_PX})
        _, reward, terminated, _, info = env.step(np.asarray(o[:2]))
        results.append((reward, terminated, info["is_success"]))
    assert results[0] == results[1] == (1.0, True, True)
