"""The gym-pusht drop-in, checked against gym-pusht 0.1.8 itself (a test extra) and a LeRobot-style loop.

Only the id changes between the two: every test below builds both with the same kwargs and holds
this env to gym-pusht's spaces, starts, units, agent, pictures and infos. The block's physics is
MuJoCo's, not pymunk's, so a pushed block is compared by behaviour (reaches the goal, scores),
never to the pixel.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import mjx_pusht  # noqa: F401  (registers the env ids)
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.rules import distance_to_tee

gym_pusht = pytest.importorskip("gym_pusht")  # a test extra: pip install 'mjx-pusht[test]'
OURS, THEIRS = "mjx_pusht/PushT-gym-pusht-v0", "gym_pusht/PushT-v0"
OBS_TYPES = ["state", "environment_state_agent_pos", "pixels", "pixels_agent_pos"]
# the block's origin for a start on the goal, through gym-pusht's reset_to_state placement quirk
# (origin = position + (0, 45) - R(angle) (0, 45)): the origin lands on (256, 256) at angle pi/4
ON_GOAL = [100.0, 100.0, 256 - 45 * np.sin(np.pi / 4), 256 - 45 + 45 * np.cos(np.pi / 4), np.pi / 4]


def both(**kwargs):
    return gym.make(THEIRS, **kwargs), gym.make(OURS, **kwargs)


@pytest.mark.parametrize("obs_type", OBS_TYPES)
def test_the_spaces_are_gym_pushts(obs_type):
    theirs, ours = both(obs_type=obs_type)
    assert ours.observation_space == theirs.observation_space  # keys, shapes, dtypes, bounds
    assert ours.action_space == theirs.action_space
    if isinstance(theirs.observation_space, gym.spaces.Dict):
        assert list(ours.observation_space.spaces) == list(theirs.observation_space.spaces)
    assert ours.metadata["render_fps"] == theirs.metadata["render_fps"] == 10
    assert ours.spec.max_episode_steps == theirs.spec.max_episode_steps == 300


def test_a_seed_starts_where_gym_pusht_starts_and_so_do_the_resets_after_it():
    theirs, ours = both(obs_type="environment_state_agent_pos")
    for seed in (0, 1, 7, 12345):
        for k in range(3):  # reset(seed=s), then two resets that continue the env's own generator
            s = seed if k == 0 else None
            (o1, i1), (o2, i2) = theirs.reset(seed=s), ours.reset(seed=s)
            np.testing.assert_allclose(o2["agent_pos"], o1["agent_pos"], atol=1e-9)
            np.testing.assert_allclose(o2["environment_state"], o1["environment_state"], atol=1e-9)
            np.testing.assert_allclose(i2["block_pose"][:2], i1["block_pose"][:2], atol=1e-9)


def test_reset_to_state_places_the_block_as_gym_pusht_does_quirk_included():
    theirs, ours = both(obs_type="state")
    # gym-pusht's own docstring example: [0, 10, 20, 30, 1] comes back as [0, 10, 57.866196, 50.686398, 1]
    o, _ = ours.reset(options={"reset_to_state": [0.0, 10.0, 20.0, 30.0, 1.0]})
    np.testing.assert_allclose(o, [0.0, 10.0, 57.866196, 50.686398, 1.0], atol=1e-6)
    rng = np.random.default_rng(0)
    for _ in range(20):
        st = [*rng.uniform(50, 450, 2), *rng.uniform(100, 400, 2), rng.uniform(-np.pi, np.pi)]
        (o1, _), (o2, _) = theirs.reset(options={"reset_to_state": st}), ours.reset(options={"reset_to_state": st})
        if distance_to_tee(frame.legacy_state_to_world(st)[:, 3:5], frame.legacy_state_to_world(st)[:, :3])[0] > 0.02:
            np.testing.assert_allclose(o2, o1, atol=1e-6)  # within a pixel, asked; to the micro-pixel, got
        else:  # a pusher dropped on the block: gym-pusht's settling step shoves the block, this reset does not
            np.testing.assert_allclose(o2[:2], o1[:2], atol=1e-6)


def test_a_free_pusher_follows_gym_pushts_pd_law_step_for_step():
    # kp 100, kv 20 at 100 Hz, on position servos under MuJoCo's Euler: the same recurrence as gym-pusht's
    theirs, ours = both(obs_type="state")
    start = {"reset_to_state": [100.0, 100.0, 420.0, 120.0, 0.0]}
    theirs.reset(options=start), ours.reset(options=start)
    for target in [(256, 256)] * 10 + [(150, 300)] * 10 + [(60, 60)] * 5:
        *_, i1 = theirs.step(np.array(target, np.float64))
        *_, i2 = ours.step(np.array(target, np.float64))
        np.testing.assert_allclose(i2["pos_agent"], i1["pos_agent"], atol=1e-6)
        np.testing.assert_allclose(i2["vel_agent"], i1["vel_agent"], atol=1e-5)
        assert i1["n_contacts"] == i2["n_contacts"] == 0


def _masks(img):
    """Each pixel to the nearest of gym-pusht's colours; the T, the goal and the agent as masks."""
    names = list(frame.COLOURS)
    pal = np.array([frame.COLOURS[n] for n in names], float)
    c = ((img[..., None, :].astype(float) - pal) ** 2).sum(-1).argmin(-1)
    idx = {n: i for i, n in enumerate(names)}
    return {"tee": np.isin(c, [idx["tee"], idx["tee_edge"]]), "goal": c == idx["goal"],
            "agent": np.isin(c, [idx["agent"], idx["agent_edge"]])}


def test_96_pixel_pictures_of_the_same_states_match_gym_pushts():
    theirs, ours = both(obs_type="pixels")
    rng = np.random.default_rng(1)
    iou = {"tee": [], "goal": [], "agent": []}
    while len(iou["tee"]) < 60:
        st = [*rng.uniform(50, 450, 2), *rng.uniform(100, 400, 2), rng.uniform(-np.pi, np.pi)]
        w = frame.legacy_state_to_world(st)
        if distance_to_tee(w[:, 3:5], w[:, :3])[0] < 0.02:
            continue  # a pusher dropped on the block: gym-pusht's settling step moves the block (see above)
        (o1, _), (o2, _) = theirs.reset(options={"reset_to_state": st}), ours.reset(options={"reset_to_state": st})
        assert o2.shape == o1.shape == (96, 96, 3) and o2.dtype == o1.dtype == np.uint8
        m1, m2 = _masks(o1), _masks(o2)
        for k in iou:
            union = (m1[k] | m2[k]).sum()
            if union:
                iou[k].append((m1[k] & m2[k]).sum() / union)
    # the agent is ~25 pixels at 96 x 96, so one pixel is 4% of its IoU: held on the mean over states
    for k, v in iou.items():
        assert np.mean(v) >= 0.9, (k, np.mean(v), np.min(v))
    assert np.min(iou["tee"]) >= 0.8 and np.min(iou["goal"]) >= 0.8


def test_an_agent_over_the_wall_is_drawn_over_it_as_gym_pusht_draws_it():
    """gym-pusht's agent is kinematic and drawn after the walls: where it passes over a wall the picture shows the
    agent. The walls here collide but are not drawn (a grey floor under a white table draws the border)."""
    theirs, ours = both(obs_type="pixels")
    rng = np.random.default_rng(2)
    shown, border = [], 0
    for x, y in [(3, 200), (509, 300), (250, 2), (300, 510), (4, 4), (508, 12)]:
        st = [x, y, *rng.uniform(150, 350, 2), rng.uniform(-np.pi, np.pi)]
        (o1, _), (o2, _) = theirs.reset(options={"reset_to_state": st}), ours.reset(options={"reset_to_state": st})
        m1, m2 = _masks(o1)["agent"], _masks(o2)["agent"]
        shown.append((m1 & m2).sum() / m1.sum())  # of gym-pusht's agent pixels, how many show the agent here too
        grey = np.array(frame.COLOURS["wall"])
        border += int((np.abs(o2.astype(int) - grey).sum(-1) < 30)[[0, -1]].any())  # a wall-grey edge row is drawn
    # measured: 0.89-1.0 (walls drawn over the agent, before: 0.13-0.40); ~10 agent pixels, so one is 10%
    assert min(shown) >= 0.85, shown
    assert border >= 4  # the border is still drawn where no agent covers it


def test_near_the_goal_coverage_and_success_are_gym_pushts_on_the_same_states():
    """gym-pusht's coverage is shapely's overlap of its pymunk polygons; the drop-in's, the task's own polygon
    arithmetic. On blocks placed around the goal (coverage 0.56-0.99, many near the 0.95 rule) they agree to
    rounding, and so does `is_success`: a gap between the two envs' success rates under one policy is not the rule."""
    theirs, ours = both(obs_type="state")
    o, _ = theirs.reset(options={"reset_to_state": [50.0, 50.0, 256.0, 256.0, np.pi / 4]})
    shift = np.asarray(o[2:4]) - 256.0  # reset_to_state's quirk (above): the block lands shifted by its angle's offset
    rng = np.random.default_rng(1)
    covered, near = [], 0
    for _ in range(60):
        st = [50.0, 50.0, *(256.0 - shift + rng.normal(0, 5, 2)), np.pi / 4 + rng.normal(0, 0.05)]
        theirs.reset(options={"reset_to_state": st}), ours.reset(options={"reset_to_state": st})
        *_, i1 = theirs.step(np.array([50.0, 50.0]))  # the pusher stays in its corner, away from the block
        *_, i2 = ours.step(np.array([50.0, 50.0]))
        assert i2["coverage"] == pytest.approx(i1["coverage"], abs=1e-12) and i2["is_success"] == i1["is_success"]
        covered.append(i1["is_success"])
        near += 0.9 < i1["coverage"] < 0.99
    assert near >= 10 and 0 < sum(covered) < len(covered)  # the rule was met and missed: the threshold was tested


def test_info_carries_gym_pushts_keys():
    theirs, ours = both(obs_type="state")
    (_, i1), (_, i2) = theirs.reset(seed=3), ours.reset(seed=3)
    assert set(i1) <= set(i2) and i2["is_success"] is False
    np.testing.assert_array_equal(i2["goal_pose"], i1["goal_pose"])
    for seed in (3, 11, 0):  # the block's pose as gym-pusht's info gives it: its angle unwrapped, not the observation's
        (o1, i1), (o2, i2) = theirs.reset(seed=seed), ours.reset(seed=seed)
        np.testing.assert_allclose(i2["block_pose"], i1["block_pose"], atol=1e-9)
        assert o2[4] == pytest.approx(o1[4], abs=1e-9)
    assert i1["block_pose"][2] < 0 < o1[4]  # seed 0 (the last) starts across gym-pusht's wrap
    *_, i1 = theirs.step(np.array([256.0, 256.0]))
    *_, i2 = ours.step(np.array([256.0, 256.0]))
    assert set(i1) <= set(i2)
    assert isinstance(i2["n_contacts"], int) and isinstance(i2["is_success"], bool)


# -- a LeRobot-style eval loop, written from LeRobot's documented behaviour -----------------------------
def preprocess_observation(observations: dict) -> dict:
    """LeRobot's `preprocess_observation`: NumPy in, torch out, with its checks (channel last, uint8)."""
    import torch

    out = {}
    if "pixels" in observations:
        img = torch.from_numpy(observations["pixels"])
        _, h, w, c = img.shape
        assert c < h and c < w, f"expect channel last images, but instead got {img.shape=}"
        assert img.dtype == torch.uint8, f"expect torch.uint8, but instead {img.dtype=}"
        out["observation.image"] = img.permute(0, 3, 1, 2).contiguous().type(torch.float32) / 255
    if "environment_state" in observations:
        out["observation.environment_state"] = torch.from_numpy(observations["environment_state"]).float()
    out["observation.state"] = torch.from_numpy(observations["agent_pos"]).float()
    return out


def lerobot_env(env_id: str, n: int, batched: bool = False, **extra):
    """LeRobot's PushT env: its gym kwargs, n copies in a SyncVectorEnv with SameStep autoreset
    (or, `batched`, the same kwargs through gym.make_vec: this project's batch)."""
    kwargs = {"obs_type": "pixels_agent_pos", "render_mode": "rgb_array", "visualization_width": 384,
              "visualization_height": 384, "max_episode_steps": 300, **extra}
    if batched:
        return gym.make_vec(env_id, num_envs=n, autoreset_mode="same_step", backend="cpu", **kwargs)
    return gym.vector.SyncVectorEnv([lambda: gym.make(env_id, **kwargs) for _ in range(n)],
                                    autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)


def rollout(env, policy, seed=0, options=None, frames=False):
    """LeRobot's `rollout` + eval bookkeeping: until every env is done; success from final_info."""
    obs, info = env.reset(seed=seed, options=options)
    max_steps = env.call("_max_episode_steps")[0]
    done = np.zeros(env.num_envs, bool)
    rewards, successes, renders, steps = [], [], [], 0
    while not done.all() and steps < max_steps:
        batch = preprocess_observation(obs)
        action = policy(batch).numpy()
        assert action.ndim == 2, "Action dimensions should be (batch, action_dim)"
        obs, reward, terminated, truncated, info = env.step(action)
        if frames:
            renders.append(np.stack(env.call("render")))
        if "final_info" in info:
            assert isinstance(info["final_info"], dict)
            success = np.where(info["_final_info"], info["final_info"]["is_success"], False)
        else:
            success = np.zeros(env.num_envs, bool)
        last = np.array(obs["agent_pos"])  # where each agent is; an episode that just ended: its final observation
        for i in np.flatnonzero(info.get("_final_obs", [])):
            fo = info["final_obs"]  # SyncVectorEnv: an object array of each env's obs; the batch: obs batched
            last[i] = fo["agent_pos"][i] if isinstance(fo, dict) else fo[i]["agent_pos"]
        rewards.append(np.where(done, 0.0, reward))
        successes.append(success & ~done)
        done = done | terminated | truncated
        steps += 1
    rewards, successes = np.stack(rewards), np.stack(successes)
    return {"pc_success": 100 * successes.any(0).mean(), "avg_max_reward": rewards.max(0).mean(),
            "steps": steps, "max_steps": max_steps, "final_agent": last, "renders": renders}


def hold(batch):
    return batch["observation.state"].double()  # target = where the agent is: it stays put


def to_centre(batch):
    import torch

    return torch.full((len(batch["observation.state"]), 2), 256.0, dtype=torch.float64)


@pytest.mark.parametrize("env_id", [THEIRS, OURS])
def test_lerobots_loop_runs_unchanged_and_a_start_on_the_goal_scores(env_id):
    env = lerobot_env(env_id, 2)
    r = rollout(env, hold, options={"reset_to_state": ON_GOAL}, frames=True)
    assert r["max_steps"] == 300
    assert r["pc_success"] == 100 and r["avg_max_reward"] == 1.0 and r["steps"] == 1
    assert r["renders"][0].shape == (2, 384, 384, 3)


@pytest.mark.parametrize("env_id", [THEIRS, OURS])
def test_lerobots_loop_a_pusher_sent_to_the_centre_arrives(env_id):
    # the block out of the way, in a corner: the pusher crosses open table to pixel (256, 256)
    env = lerobot_env(env_id, 2, max_episode_steps=40)
    r = rollout(env, to_centre, options={"reset_to_state": [100.0, 100.0, 420.0, 80.0, 0.0]})
    assert r["max_steps"] == 40 and r["steps"] == 40  # the kwarg is the limit, and call() says so
    np.testing.assert_allclose(r["final_agent"], 256.0, atol=0.5)
    assert r["pc_success"] == 0


def test_lerobots_loop_through_make_vec_gives_the_same_results():
    one_by_one = lerobot_env(OURS, 3)
    batch = lerobot_env(OURS, 3, batched=True)
    assert batch.single_observation_space == one_by_one.single_observation_space
    for policy, options in ((hold, {"reset_to_state": ON_GOAL}), (to_centre, None)):
        a, b = rollout(one_by_one, policy, seed=5, options=options), rollout(batch, policy, seed=5, options=options)
        assert (a["pc_success"], a["avg_max_reward"], a["steps"]) == (b["pc_success"], b["avg_max_reward"], b["steps"])
        np.testing.assert_allclose(b["final_agent"], a["final_agent"], atol=1e-9)
    assert batch.call("_max_episode_steps") == (300,) * 3


def test_the_drop_in_refuses_what_it_cannot_be_in_one_line():
    with pytest.raises(ValueError, match="obs_type"):
        gym.make(OURS, obs_type="keypoints")
    with pytest.raises(ValueError, match="pymunk"):
        gym.make(OURS, damping=0.5)
    with pytest.raises(ValueError, match="square"):
        gym.make(OURS, obs_type="pixels", observation_width=96, observation_height=64)
    env = gym.make(OURS)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.step(np.zeros(3))
