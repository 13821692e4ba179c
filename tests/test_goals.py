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


def test_a_seeds_goal_is_drawn_from_its_key_inside_the_walls_with_room_to_push():
    from mjx_pusht.task.controllers import seed_key, uniform_hash

    seeds = np.arange(3000)
    g = goal_poses(seeds, "chapter")
    u = [2 * float(uniform_hash(seed_key([17]), 2**32 - 1, lane)[0]) - 1 for lane in range(3)]
    half = WORKSPACE_HALF - np.hypot(0.015, 0.105) - ROOM
    np.testing.assert_allclose(g[17], [half * u[0], half * u[1], np.pi * u[2]], rtol=0, atol=1e-15)
    corners = keypoints(g).reshape(-1, 8, 2)
    assert np.abs(corners).max() <= WORKSPACE_HALF - ROOM + 1e-12
    assert g[:, 0].min() < -0.2 and g[:, 0].max() > 0.2 and g[:, 1].min() < -0.2 and g[:, 1].max() > 0.2  # spread out
    lo, hi = frame.WALL_INNER_PX  # gym-pusht's walls, in its pixels (1 mm each): a square turned by pi/4 in the world
    px = frame.to_px(keypoints(goal_poses(seeds, "gym-pusht")).reshape(-1, 2))
    assert lo + ROOM / frame.PX - 1e-6 <= px.min() and px.max() <= hi - ROOM / frame.PX + 1e-6
    assert px.min() < lo + ROOM / frame.PX + 20 and px.max() > hi - ROOM / frame.PX - 20  # reaching the bounds


def goal_episodes(task: str, seeds, max_steps: int):
    """The task's expert on random goals (MuJoCo C): every step's reward checked
    against `coverage_one` of the T in its goal's frame. Returns (the best coverage seen, which episodes reached 0.95)."""
    t = get(task)
    env = PushTEnv.for_task(task, max_steps=max_steps, goal="random")
    s = env.reset(seeds)
    fixed = PushTEnv.for_task(task).reset(seeds)
    np.testing.assert_array_equal(s.obs["state"], fixed.obs["state"])  # a seed starts where it always did
    np.testing.assert_array_equal(s.obs["goal"], goal_poses(seeds, t.variant))
    assert "goal" not in fixed.obs and "goal" not in fixed.carry  # a fixed goal carries nothing
    ctrl = t.controller("expert", goal="random")  # each expert pushes toward obs["goal"] itself (reads_goal)
    carry = ctrl.init(s.key)
    reached, best = np.zeros(len(seeds), bool), 0.0
    while not s.carry["ep"]["done"].all():
        action, carry = ctrl.act(carry, s.obs, s.step, s.key)
        live = ~s.carry["ep"]["done"]
        s = env.step(s, action)
        for i in np.flatnonzero(live):
            mine = coverage_one(*to_goal_frame(s.obs["state"][i, 2:5], s.obs["goal"][i]).tolist())
            assert abs(s.reward[i] - mine) < 1e-12
            reached[i] |= mine >= 0.95
            best = max(best, mine)
    np.testing.assert_array_equal(s.metrics["success"], reached)
    return best, reached


@pytest.mark.parametrize("task", ["gym-pusht", "chapter"])
def test_reward_follows_the_goal_step_by_step(task):
    best, _ = goal_episodes(task, np.arange(2, 6), 80)
    assert best > 0.3  # the check saw Ts overlapping their goals, not only zeros


@pytest.mark.slow  # 16 episodes of the experts (about 10 s on 2 cores)
@pytest.mark.parametrize("task", ["gym-pusht", "chapter"])
def test_the_expert_follows_a_random_goal_and_succeeds_by_it(task):
    _, reached = goal_episodes(task, np.arange(8), 300)
    assert reached.sum() >= 6


def test_a_controller_of_the_fixed_goal_acts_from_the_goals_frame_and_its_action_is_put_back():
    """Seen from the goal's frame, a controller that heads for the T (a velocity, or the T's position as a target)
    commands what it commands in the world: the frame's rotation and shift are undone exactly."""
    from mjx_pusht.task.controllers import FromFunction

    rng = np.random.default_rng(0)
    obs = {"state": rng.uniform(-0.3, 0.3, (6, 5)), "goal": goal_poses(np.arange(6), "chapter")}
    for kind, fn in (("velocity", lambda o, t: o["state"][:, 2:4] - o["state"][:, 0:2]),
                     ("position", lambda o, t: o["state"][:, 2:4])):
        ctrl = FromFunction(name=kind, action_type=kind, fn=fn)
        seen, _ = in_goal_frame(ctrl).act(None, obs, 0, None)
        np.testing.assert_allclose(seen, fn(obs, 0), rtol=0, atol=1e-15)
    alone = {"state": obs["state"]}  # no goal: the controller itself
    np.testing.assert_array_equal(in_goal_frame(ctrl).act(None, alone, 0, None)[0], ctrl.act(None, alone, 0, None)[0])


def test_goal_options_are_checked_in_one_line():
    with pytest.raises(ConfigError, match="unknown goal 'moving'; choose from fixed, random"):
        PushTEnv(goal="moving")


@pytest.mark.parametrize("obs_type", ["pixels", "pixels_agent_pos"])
def test_pixel_observations_of_random_goals_show_the_goal_and_keep_their_spaces(obs_type):
    """Pixels draw each episode's target at its goal (test_pixels.py checks where); the observation keeps the
    pixel space (the goal is in the picture and in info["goal_pose"]), single and vector alike."""
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    import mjx_pusht  # noqa: F401

    one = gym.make("mjx_pusht/PushT-v0", obs_type=obs_type, goal="random", observation_size=32)
    check_env(one.unwrapped, skip_render_check=True)
    obs, info = one.reset(seed=5)
    assert one.observation_space.contains(obs) and info["goal_pose"].shape == (3,)
    many = gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu", obs_type=obs_type, goal="random",
                        observation_size=32)
    obs, info = many.reset(seed=5)
    assert many.observation_space.contains(obs) and info["goal_pose"].shape == (2, 3)
    obs, *_, info = many.step(np.zeros((2, 2)))
    assert many.observation_space.contains(obs)
    one.close(), many.close()


@pytest.mark.slow  # compiles MJX-JAX's and MJX-Warp's steps (about 30 s on 2 cores)
def test_a_seed_draws_the_same_goal_on_every_backend_and_each_scores_against_it():
    rewards = {}
    for b in ("cpu", "mjx-jax", "mjx-warp"):
        env = PushTEnv.for_task("gym-pusht", backend=b, goal="random")
        s = env.reset(np.arange(4))
        for _ in range(2):  # push toward the T's centre
            s = env.step(s, np.asarray(s.obs["state"][:, 2:4]))
        goal, final = np.asarray(s.obs["goal"], np.float64), np.asarray(s.carry["final"], np.float64)
        # drawn inside each backend's reset from the seed's key: the host's numbers, in the backend's float32
        np.testing.assert_allclose(goal, goal_poses(np.arange(4), "gym-pusht"), rtol=0, atol=1e-6)
        mine = [coverage_one(*to_goal_frame(final[i], goal[i]).tolist()) for i in range(4)]
        np.testing.assert_allclose(np.asarray(s.reward), mine, atol=1e-6)
        rewards[b] = np.asarray(s.reward)
    assert rewards["cpu"].max() > 0.05  # the goals' Ts overlap the pushed ones: the check saw coverage


def test_a_partial_reset_draws_the_new_episodes_goals_and_keeps_the_others():
    env = PushTEnv.for_task("chapter", goal="random")
    s = env.step(env.reset([0, 1, 2]), np.zeros((3, 2)))
    s2 = env.reset_where(s, np.array([False, True, False]), seeds=[7])
    np.testing.assert_array_equal(s2.obs["goal"], [s.obs["goal"][0], goal_poses([7], "chapter")[0], s.obs["goal"][2]])
    assert s2.reward[1] == 0 and s2.step[1] == 0 and s2.step[0] == 1


def test_gym_pusht_itself_scores_its_episodes_against_the_drawn_goal():
    """The gym-pusht backend sets gym-pusht's own goal_pose: the coverage gym-pusht reports (shapely's polygons)
    is that of its final T against the seed's drawn goal, computed here."""
    from mjx_pusht.backends.gym_pusht import GymPushtBackend
    from mjx_pusht.scenario import Scenario

    task, seeds = get("gym-pusht"), np.array([0, 1])
    sc = Scenario(task.scene(), reset=task.reset, controller=task.controller("expert", goal="random"),
                  episode=task.episode(max_steps=80, goal="random"))
    backend = GymPushtBackend(sc, workers=1)
    r = backend.run(seeds)
    backend.close()
    goals = goal_poses(seeds, "gym-pusht")
    mine = [coverage_one(*to_goal_frame(r.final[i], goals[i]).tolist()) for i in range(len(seeds))]
    np.testing.assert_allclose(r.episode["coverage"], mine, atol=1e-6)
    assert max(mine) > 0.3  # the expert pushed the T onto its goal, in gym-pusht's own physics


def test_eval_runs_random_goals_and_what_cannot_take_them_says_so_in_one_line(tmp_path, capsys):
    from mjx_pusht.cli import main
    from mjx_pusht.study.evaluate import evaluate

    s = evaluate("expert", np.arange(4), tmp_path / "e", backend="cpu", task="gym-pusht", goal="random", max_steps=20,
                 rerun=False, progress=False)
    assert s["config"]["goal"] == "random"
    capsys.readouterr()
    for argv, why in ((["train", "--algo", "ppo", "--goal", "random", "--no-rerun"], "--goal random trains a goal-"),
                      (["compare", "--goal", "random"], "--success-threshold and --goal are a controller's")):
        assert main([*argv, "--out", str(tmp_path / "o")]) in (1, 2)
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith(f"mjx-pusht: error: {why}"), err
        assert not (tmp_path / "o").exists()


def test_the_gymnasium_envs_observe_the_goal_beside_the_t_and_reward_toward_it():
    import gymnasium as gym

    import mjx_pusht  # noqa: F401

    goal = goal_poses([3], "chapter")[0]
    env = gym.make("mjx_pusht/PushT-v0", goal="random", obs_type="keypoints")
    obs, info = env.reset(seed=3)
    np.testing.assert_array_equal(info["goal_pose"], goal)
    np.testing.assert_allclose(obs[16:], keypoints(goal), rtol=0, atol=1e-15)  # the goal T's outline after the T's
    obs, reward, *_ = env.step(np.array([0.5, 0.5]))
    assert env.observation_space.contains(obs) and obs.shape == (32,)
    tee = env.unwrapped._state.obs["state"][0, 2:5]
    assert abs(reward - coverage_one(*to_goal_frame(tee, goal).tolist())) < 1e-12
    drop_in = gym.make("mjx_pusht/PushT-gym-pusht-v0", goal="random")  # gym-pusht's units: pixels, its angle
    obs, info = drop_in.reset(seed=3)
    origin, angle = frame.pose_to_px(goal_poses([3], "gym-pusht"))
    np.testing.assert_allclose(obs[5:], [*origin[0], angle[0]], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(info["goal_pose"], obs[5:])
    assert drop_in.observation_space.contains(obs)


def chapter_policy(path, goal: bool):
    """A small untrained student of the chapter's task, written as `train` writes one (`goal`: --goal random's)."""
    import jax
    import jax.numpy as jnp

    from mjx_pusht.task.memory import CHAPTER
    from mjx_pusht.train.policy import feature_size, network, save

    width = feature_size("state", goal=goal)
    params = network((32,), "relu", 0, 2 + CHAPTER.size).init(jax.random.key(3), jnp.zeros((1, width)))["params"]
    save(path, params, {"obs_type": "state", "activation": "relu", "in_mean": [0.0] * width, "in_std": [0.1] * width,
                        "method": "dagger", "config": {}} | ({"goal": True} if goal else {}))
    return f"policy:{path}"


def test_a_goal_conditioned_policy_reads_the_goal_and_one_without_sees_it_from_the_goals_frame(tmp_path):
    state = np.array([[0.1, -0.2, 0.05, 0.02, 0.3]])
    goal = goal_poses([5], "chapter")
    task = get("chapter")
    reader = task.controller(chapter_policy(tmp_path / "g.msgpack", goal=True), goal="random")
    assert reader.reads_goal and reader.name.startswith("policy:")  # not wrapped: it reads obs["goal"] itself
    carry = reader.init(np.zeros((1, 2), np.uint32))
    toward = reader.act(carry, {"state": state, "goal": goal}, 0, None)[0]
    elsewhere = reader.act(carry, {"state": state, "goal": goal + 0.1}, 0, None)[0]
    at_centre = reader.act(carry, {"state": state}, 0, None)[0]  # the fixed goal: the target at the origin
    np.testing.assert_array_equal(at_centre, reader.act(carry, {"state": state, "goal": np.zeros((1, 3))}, 0, None)[0])
    assert np.abs(toward - elsewhere).max() > 0  # its action depends on where the goal is
    # a policy of the fixed goal (no "goal" in its file, as every policy before goals) loads and runs as it did,
    # and on random goals acts from the goal's frame: its action there is its action on the scene seen from the goal
    plain = task.controller(chapter_policy(tmp_path / "p.msgpack", goal=False), goal="random")
    assert isinstance(plain, type(in_goal_frame(plain.inner))) and not plain.inner.reads_goal
    seen = np.concatenate([to_goal_frame(state[:, 0:2], goal), to_goal_frame(state[:, 2:5], goal)], axis=-1)
    own = plain.inner.act(carry, {"state": seen}, 0, None)[0]
    c, s = np.cos(goal[0, 2]), np.sin(goal[0, 2])
    np.testing.assert_allclose(plain.act(carry, {"state": state, "goal": goal}, 0, None)[0],
                               own @ np.array([[c, s], [-s, c]]), rtol=0, atol=1e-12)


def test_a_controller_that_looks_at_pixels_for_the_fixed_goal_is_refused_random_goals_in_one_line(monkeypatch):
    """A state controller of the fixed goal sees each episode from its goal's frame; a picture cannot be turned
    that way (it shows the target at the goal), so one that looks is refused rather than handed a mixed view."""
    import dataclasses
    from typing import ClassVar

    from mjx_pusht.task import controllers
    from mjx_pusht.task.controllers import FromFunction

    @dataclasses.dataclass(frozen=True, eq=False)
    class Looks(FromFunction):
        pixels: ClassVar[int] = 32

    monkeypatch.setattr(controllers, "load", lambda spec, **kw: Looks(name=spec, action_type="velocity"))
    for task in ("chapter", "gym-pusht"):
        assert get(task).controller("policy:p.msgpack").pixels == 32  # the fixed goal: used as it is
        with pytest.raises(ConfigError, match=r"^policy:p.msgpack looks at pixels and was made for the fixed goal"):
            get(task).controller("policy:p.msgpack", goal="random")
