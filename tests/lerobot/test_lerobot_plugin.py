"""The plugin, as LeRobot finds it: `register_third_party_plugins()` imports it by its distribution name and
`--env.type=mjx_pusht` is LeRobot's PushtEnv config, field for field, whose `create_envs` hands LeRobot's eval
loop what it reads of an env (checked with LeRobot's own functions, and against gym-pusht's own starts)."""

from __future__ import annotations

import dataclasses

import gym_pusht  # noqa: F401 - registers gym_pusht/PushT-v0, the peer
import gymnasium as gym
import numpy as np
import pytest
from lerobot.envs.configs import EnvConfig, PushtEnv
from lerobot.envs.factory import make_env, make_env_config
from lerobot.envs.utils import NEW_ROLLOUT_OPTION, env_to_policy_features, preprocess_observation
from lerobot.utils.import_utils import register_third_party_plugins

SEEDS = [1000, 1001]  # lerobot-eval seeds its rollouts from cfg.seed = 1000 upward


@pytest.fixture(scope="module")
def registered():
    register_third_party_plugins()
    return EnvConfig.get_choice_class("mjx_pusht")


def test_the_plugin_registers_pushtenvs_fields(registered):
    ours, theirs = registered(), PushtEnv()
    names = {f.name for f in dataclasses.fields(theirs)}
    assert names <= {f.name for f in dataclasses.fields(ours)}
    for name in names - {"task"}:
        assert getattr(ours, name) == getattr(theirs, name), name
    assert env_to_policy_features(ours) == env_to_policy_features(theirs)
    small = make_env_config("mjx_pusht", observation_height=96, observation_width=96)
    assert small.features["pixels"].shape == (96, 96, 3)
    with pytest.raises(ValueError, match="--env.backend"):
        make_env_config("mjx_pusht", backend="gpu")


def gym_pusht_starts(seeds):
    env = gym.make("gym_pusht/PushT-v0", obs_type="pixels_agent_pos")
    starts = [env.reset(seed=s) for s in seeds]
    return np.array([o["agent_pos"] for o, _ in starts]), np.array([i["block_pose"] for _, i in starts])


@pytest.mark.warp
def test_create_envs_gives_one_batch_on_mjx_warp_that_lerobots_loop_reads(registered):
    cfg = make_env_config("mjx_pusht", backend="mjx-warp", observation_height=96, observation_width=96,
                          episode_length=3)
    envs = make_env(cfg, n_envs=2)
    assert list(envs) == ["mjx_pusht"] and list(envs["mjx_pusht"]) == [0]
    vec = envs["mjx_pusht"][0]
    assert vec.num_envs == 2 and vec.unwrapped.backend == "mjx-warp"  # one vector env: the batch
    obs, info = vec.reset(seed=SEEDS, options={NEW_ROLLOUT_OPTION: True})
    assert obs["pixels"].shape == (2, 96, 96, 3) and obs["pixels"].dtype == np.uint8
    agent, block = gym_pusht_starts(SEEDS)
    assert np.array_equal(obs["agent_pos"], agent)  # gym-pusht's own starts, seed for seed
    assert np.allclose(info["block_pose"][:, :2], block[:, :2], atol=1e-3)
    batch = preprocess_observation(obs)  # LeRobot's own conversion: torch.from_numpy, HWC uint8 -> CHW float
    assert tuple(batch["observation.image"].shape) == (2, 3, 96, 96)
    assert tuple(batch["observation.state"].shape) == (2, 2)
    assert vec.call("_max_episode_steps") == (3, 3)
    assert vec.call("task_description")[0] == "Push the T-shaped block onto the T-shaped target."
    assert vec.unwrapped.metadata["render_fps"] == 10
    for t in range(3):
        obs, reward, terminated, truncated, info = vec.step(np.full((2, 2), 256.0, np.float32))
        assert info["is_success"].shape == (2,)
    assert truncated.all() and "final_info" in info and info["final_info"]["is_success"].shape == (2,)
    assert np.stack(vec.call("render")[:2]).shape == (2, 96, 96, 3)
    vec.close()


def test_elsewhere_create_envs_is_lerobots_usual_vector_env_and_a_seed_starts_the_same_in_any_batch(registered):
    cfg = make_env_config("mjx_pusht", backend="cpu", observation_height=96, observation_width=96)
    vec = make_env(cfg, n_envs=3)["mjx_pusht"][0]
    assert isinstance(vec, gym.vector.SyncVectorEnv) and vec.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    obs, info = vec.reset(seed=[999, *SEEDS], options={NEW_ROLLOUT_OPTION: True})
    agent, _ = gym_pusht_starts(SEEDS)
    assert np.array_equal(obs["agent_pos"][1:], agent)
    assert vec.call("task")[0] == "PushT-gym-pusht-v0"
    vec.close()


def test_env_randomize_reaches_the_drop_in_and_a_bad_range_is_refused_at_the_config(registered):
    """`--env.randomize` is `eval --randomize`'s text; the envs LeRobot builds draw each episode's gains from its seed
    (info["physics"]); nothing asked for, gym_kwargs are LeRobot's PushtEnv's as before."""
    from mjx_pusht.model.params import CURRENT
    from mjx_pusht.model.randomize import factors

    assert "randomize" not in registered().gym_kwargs
    cfg = make_env_config("mjx_pusht", observation_height=96, observation_width=96, backend="cpu",
                          obs_type="environment_state_agent_pos", randomize="kv=0.5:2")
    assert cfg.gym_kwargs["randomize"] == {"kv": (0.5, 2.0)}
    vec = cfg.create_envs(2)["mjx_pusht"][0]
    _, info = vec.reset(seed=SEEDS)
    own = CURRENT["kv"](vec.envs[0].unwrapped._env.model)
    np.testing.assert_array_equal(info["physics"]["kv"], factors((("kv", (0.5, 2.0)),), SEEDS)[:, 0] * own)
    vec.close()
    with pytest.raises(ValueError, match="tee_mass means nothing on the gym-pusht task"):
        make_env_config("mjx_pusht", randomize="tee_mass=0.5:2")
