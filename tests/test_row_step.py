"""The single envs' row step (envs/row.py: one world's control step in plain floats) is the array path's control
step to the bit, and a broken world stays loud on it: every gymnasium output and every field of the functional
state, over whole random episodes of both ids, against the same env with `row_step = False`."""

from __future__ import annotations

import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import mjx_pusht  # noqa: F401  (registers the ids)
import mjx_pusht.envs.common as common
from mjx_pusht import validate
from mjx_pusht.envs.functional import State
from mjx_pusht.errors import ConfigError

V0, DROP_IN = "mjx_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"


def same(a, b, path=""):
    """Equal to the bit (signed zeros and NaN payloads included), of the same types, all the way down."""
    assert type(a) is type(b), (path, type(a), type(b))
    if isinstance(a, dict):
        assert a.keys() == b.keys(), (path, a.keys(), b.keys())
        for k in a:
            same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            same(x, y, f"{path}[{i}]")
    elif isinstance(a, np.ndarray):
        assert (a.dtype, a.shape) == (b.dtype, b.shape) and a.tobytes() == b.tobytes(), (path, a, b)
    else:
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes(), (path, a, b)


def same_state(s1: State, s2: State):
    for field in State._fields:
        if field != "data":
            same(getattr(s1, field), getattr(s2, field), field)
    d1, d2 = s1.data, s2.data
    for name in ("qpos", "qvel", "sens"):  # every physics step of the last control step
        same(getattr(d1, name), getattr(d2, name), name)
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    m = d1.models[0]
    st = [np.empty(mujoco.mj_stateSize(m, spec)) for _ in range(2)]
    mujoco.mj_getState(m, d1.datas[0], st[0], spec)
    mujoco.mj_getState(m, d2.datas[0], st[1], spec)
    same(st[0], st[1], "MjData")


@pytest.fixture
def count_rows(monkeypatch):
    """How many steps the row step computed (not None) and how many it left to the array path."""
    counts = {"row": 0, "array": 0, "row_terminated": 0}
    step_row = common.step_row

    def counted(*args):
        new = step_row(*args)
        counts["row" if new is not None else "array"] += 1
        counts["row_terminated"] += new is not None and bool(new.terminated[0])
        return new

    monkeypatch.setattr(common, "step_row", counted)
    return counts


def _pair(make):
    fast, slow = make(), make()
    slow.unwrapped.row_step = False
    return fast, slow


def _episodes(make, episodes, steps, action, start=None):
    """Run the row step and the array path side by side on the same seeds and actions; returns the successes."""
    fast, slow = _pair(make)
    rng = np.random.default_rng(0)
    successes = 0
    for e in range(episodes):
        options = {} if start is None else {"reset_to_state": start(rng)}
        same(fast.reset(seed=e, options=options), slow.reset(seed=e, options=options), "reset")
        for _ in range(steps):
            a = action(rng)
            out = fast.step(a)
            same(out, slow.step(a), "step")
            same_state(fast.unwrapped._state, slow.unwrapped._state)
            if out[2] or out[3]:
                successes += bool(out[2])
                break
    return successes


def _velocity(rng):  # past the action space both ways (clipped), float32 as spaces sample, float64 too
    a = rng.uniform(-1.3, 1.3, 2)
    return a.astype(np.float32) if rng.random() < 0.7 else a


def _target(rng):  # gym-pusht's pixel targets, past the window both ways
    a = rng.uniform(-20.0, 532.0, 2)
    return a.astype(np.float32) if rng.random() < 0.7 else a


def _below_goal(rng):
    """[tee x, y, yaw, pusher x, y] in metres: the T a few mm south of the goal (coverage below 0.95), the
    pusher just under its stem, so pushing north carries it through success."""
    d = rng.uniform(0.002, 0.008)
    return [rng.normal(0, 0.001), -d, rng.normal(0, 0.01), 0.0, -d - 0.105 - 0.016]


def _to_drop_in(start):
    """A world start as the drop-in's reset_to_state [agent x, y, block x, y, angle] in pixels (gym-pusht turns
    the block about its centre of gravity, 45 px down its axis, after placing it: undone here)."""
    from mjx_pusht.model import gym_pusht as frame

    (ox, oy), angle = (v.tolist() for v in frame.pose_to_px(np.array(start[:3])))
    ax, ay = frame.to_px(np.array(start[3:5])).tolist()
    return [ax, ay, ox - np.sin(angle) * 45, oy - 45 + np.cos(angle) * 45, angle]


def _north(rng):  # PushT-v0: push north at about 0.1 m/s
    return np.array([rng.normal(0, 0.01), 0.1 + rng.normal(0, 0.01)], np.float32)


def _north_px(rng):  # the drop-in: a target that leaves the T about on the goal, north of the pusher
    from mjx_pusht.model import gym_pusht as frame

    return frame.to_px(np.array([rng.normal(0, 0.002), -0.1195])).astype(np.float32)


@pytest.mark.parametrize("env_id, action", [(V0, _velocity), (DROP_IN, _target)])
def test_random_episodes_are_the_array_paths_to_the_bit(env_id, action, count_rows):
    _episodes(lambda: gym.make(env_id), 4, 300, action)
    assert count_rows["row"] >= 0.98 * (count_rows["row"] + count_rows["array"])  # the row step did the work


@pytest.mark.parametrize("env_id, action, start", [(V0, _north, _below_goal),
                                                   (DROP_IN, _north_px, lambda r: _to_drop_in(_below_goal(r)))])
def test_episodes_that_succeed_and_starts_on_the_goal_are_the_array_paths(env_id, action, start, count_rows):
    assert _episodes(lambda: gym.make(env_id), 12, 40, action, start) >= 10
    assert count_rows["row_terminated"] >= 8  # termination reached on the row step, again and again
    # exactly on the goal: PushT-v0's episode is over at reset; the drop-in's first step scores it
    on_goal = [0.0, 0.0, 0.0, 0.0, -0.2]
    _episodes(lambda: gym.make(env_id), 2, 5, action, lambda rng: on_goal if env_id == V0 else _to_drop_in(on_goal))


@pytest.mark.parametrize("env_id, kwargs, action", [
    (V0, {"action_type": "position", "obs_type": "keypoints"}, lambda r: r.uniform(-0.45, 0.45, 2)),
    (V0, {"obs_type": "pixels_agent_pos"}, _velocity),
    (DROP_IN, {"obs_type": "environment_state_agent_pos"}, _target),
    (DROP_IN, {"obs_type": "pixels_agent_pos"}, _target),
])
def test_other_observations_and_actions_are_the_array_paths(env_id, kwargs, action, count_rows):
    _episodes(lambda: gym.make(env_id, **kwargs), 2, 40, action)
    assert count_rows["row"] > 60


def test_the_envs_own_step_limit_truncates_as_the_array_path_does(count_rows):
    from mjx_pusht.envs.gym import PushTGymEnv

    fast, slow = _pair(lambda: PushTGymEnv(max_episode_steps=12))
    for env in (fast, slow):
        env.reset(seed=3)
    rng = np.random.default_rng(1)
    for k in range(12):
        a = _velocity(rng)
        out = fast.step(a)
        same(out, slow.step(a))
        same_state(fast._state, slow._state)
    assert out[3] and not out[2] and count_rows["row"] >= 10


@pytest.mark.slow
@pytest.mark.parametrize("env_id, action", [(V0, _velocity), (DROP_IN, _target)])
def test_forty_random_episodes_are_the_array_paths_to_the_bit(env_id, action, count_rows):
    _episodes(lambda: gym.make(env_id), 40, 300, action)


@pytest.mark.filterwarnings("ignore:invalid value encountered")  # the trials with a NaN or inf in the state
def test_the_drop_ins_view_in_floats_is_gym_views_to_the_bit():
    from mjx_pusht.envs.gym_pusht import OBS_TYPES, gym_view, gym_view_row

    rng = np.random.default_rng(4)
    for trial in range(3000):
        state = np.concatenate([rng.uniform(-0.4, 0.4, 4), rng.uniform(-10, 10, 1)])
        if trial % 3 == 0:  # the pusher against the T, or a T corner against a wall (n_contacts either way)
            state[0:2] = state[2:4] + rng.normal(0, 0.03, 2)
        if trial % 50 == 1:
            state[rng.integers(5)] = [np.nan, np.inf, -np.inf][trial % 3]
        obs = {"state": state, "pusher_vel": rng.normal(0, 1, 2), "pixels": np.zeros((8, 8, 3), np.uint8)}
        for obs_type in OBS_TYPES:
            cov, term = float(rng.random()), bool(trial % 2)
            out, info = gym_view(obs_type, obs, cov, term, np, np.float64)
            info["n_contacts"] = int(info["n_contacts"])  # a Python int in the single env's info, as gym-pusht's
            same(gym_view_row(obs_type, obs, cov, term), (out, info), f"trial {trial} {obs_type}")


def test_one_action_as_floats_is_the_validation_layers():
    rng = np.random.default_rng(5)
    values = [rng.uniform(-2, 2, 2).astype(dt) for dt in (np.float32, np.float64) for _ in range(200)]
    values += [np.array([-0.0, 0.0]), np.array([1.0, -1.0]), np.array([3, -7]), [0.5, 2.0], (0.1, -0.3),
               np.array([0.5, 1e300])]
    for v in values:
        same(validate.action_pair(v, -1.0, 1.0), tuple(validate.actions(v, (2,), -1.0, 1.0).tolist()), repr(v))
    for bad in (np.array([np.nan, 0.0], np.float32), np.array([0.0, np.inf]), np.zeros(3), np.zeros((1, 2)),
                np.array(["a", "b"])):
        with pytest.raises(ConfigError) as slow:
            validate.actions(bad, (2,), -1.0, 1.0)
        with pytest.raises(ConfigError, match=str(slow.value).replace("(", r"\(").replace(")", r"\)")
                           .replace("[", r"\[").replace("]", r"\]")):
            validate.action_pair(bad, -1.0, 1.0)


def _broken(env_id, row_step, breaks):
    """One env's step after `breaks(MjData)` mid-episode: (info, warnings raised)."""
    env = gym.make(env_id).unwrapped
    env.row_step = row_step
    env.reset(seed=2)
    for _ in range(5):
        env.step(env.action_space.sample())
    breaks(env._state.data.datas[0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        info = env.step(env.action_space.sample())[-1]
    return info, [w for w in caught if "non-finite or left the walls" in str(w.message)]


def _kick(d):  # 1e11 m/s: past mjMAXVAL, MuJoCo resets the MjData (whose next states look sane) and counts it
    d.qvel[2] = 1e11


def _through_the_wall(d):  # the T's joints beyond the east wall (0.39 m), as a missed contact would leave it
    d.qpos[0] = 0.5


@pytest.mark.parametrize("env_id", [V0, DROP_IN])
@pytest.mark.parametrize("row_step", [True, False])
def test_a_world_mujoco_had_to_reset_is_flagged_and_warned_about_on_both_paths(env_id, row_step):
    info, warned = _broken(env_id, row_step, _kick)
    assert not info["finite"] and warned


@pytest.mark.parametrize("env_id", [V0, DROP_IN])
@pytest.mark.parametrize("row_step", [True, False])
def test_a_tee_outside_the_walls_is_flagged_and_warned_about_on_both_paths(env_id, row_step):
    info, warned = _broken(env_id, row_step, _through_the_wall)
    assert not info["contained"] and warned


def test_the_vector_env_flags_only_the_world_mujoco_reset():
    envs = gym.make_vec(DROP_IN, num_envs=3, backend="cpu")  # (the id whose kicked world MuJoCo resets)
    envs.reset(seed=0)
    _kick(envs._state.data.datas[1])
    with pytest.warns(RuntimeWarning, match="non-finite or left the walls"):
        *_, info = envs.step(np.full((3, 2), 256.0))
    assert info["finite"].tolist() == [True, False, True]


def test_the_state_observations_yaw_wrapped_in_floats_is_wrap_angles():
    from mjx_pusht.envs.gym import wrap_yaw
    from mjx_pusht.task.rules import wrap_angle

    rng = np.random.default_rng(6)
    yaws = np.concatenate([rng.uniform(-20, 20, 20000), np.arange(-6, 7) * np.pi, [0.0, -0.0, 1e300, -1e300]])
    yaws = np.concatenate([yaws, np.nextafter(yaws, np.inf), np.nextafter(yaws, -np.inf)])
    same(np.array([wrap_yaw(y) for y in yaws.tolist()]), wrap_angle(yaws))
