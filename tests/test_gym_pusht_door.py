"""gym-pusht's own door: a committed policy in a plain gym-pusht loop (`GymPushtPolicy` in
`gym.make("gym_pusht/PushT-v0")`, as docs/task.md tells a user to run it) and `eval --backend gym-pusht` are the
same episodes, whichever way gym-pusht's observation wraps the block's angle."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.study.evaluate import evaluate
from mjx_pusht.task.rules import yaw_in_window
from mjx_pusht.task.tasks import TASKS

gym_pusht = pytest.importorskip("gym_pusht")  # a test extra, the peer
gym = pytest.importorskip("gymnasium")

POLICIES = Path(__file__).resolve().parents[1] / "outputs" / "reports" / "train"
PPO = POLICIES / "ppo-state-gym-pusht-h200" / "seed-0" / "policy.msgpack"
DAGGER = POLICIES / "dagger-state-gym-pusht-h200" / "seed-0" / "policy.msgpack"
PIXELS = str(POLICIES / "dagger-pixels-gym-pusht-h200-16k" / "seed-{}" / "policy.msgpack")
# Starts that gym-pusht's observation shows 2 pi away from the block's body angle (it wraps to [0, 2 pi)), on which
# the committed PPO policy failed in a plain loop while eval (which read the body) scored them; and two that do not
ACROSS_THE_WRAP = [2000000000, 2000000016, 2000000024, 2000000047]
SEEDS = ACROSS_THE_WRAP + [2000000001, 2000000002]


def plain_loop(path, seeds):
    """The docs' snippet, per seed: (success, steps to success, block x, y, angle at the end)."""
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    policy = GymPushtPolicy(path)
    env = gym.make("gym_pusht/PushT-v0", obs_type=policy.obs_type)
    out, wrapped = [], []
    for seed in seeds:
        obs, info = env.reset(seed=int(seed))
        wrapped.append(policy.obs_type == "state" and not math.isclose(obs[4], env.unwrapped.block.angle))
        policy.reset(seed=int(seed))
        steps, first = 0, None
        while True:
            obs, _, terminated, truncated, info = env.step(policy(obs))
            steps += 1
            first = steps if info["is_success"] and first is None else first
            if terminated or truncated:
                break
        b = env.unwrapped.block
        out.append((first is not None, first, *b.position, b.angle))
    return out, wrapped


def eval_rows(path, seeds, tmp_path):
    from mjx_pusht.io.outputs import read_table

    evaluate(f"policy:{path}", np.array(seeds), tmp_path, backend="gym-pusht", task="gym-pusht", rerun=False,
             progress=False)
    t = read_table(tmp_path / "per_episode.parquet")
    origin, angle = frame.pose_to_px(np.stack([t["tee_final_x"], t["tee_final_y"], t["tee_final_yaw"]], -1))
    return [(bool(ok), None if not ok else int(n), *o, a)
            for ok, n, o, a in zip(t["success"], t["steps_to_success"], origin, angle)]


def assert_same_episodes(loop, ev):
    for a, b in zip(loop, ev, strict=True):
        assert a[:2] == b[:2]  # success, steps to success
        assert a[2:4] == pytest.approx(b[2:4], abs=1e-6)  # the block's final position, pixels
        assert math.remainder(a[4] - b[4], 2 * math.pi) == pytest.approx(0, abs=1e-9)


def test_the_committed_ppo_policy_in_a_plain_gym_pusht_loop_is_eval_on_gym_pusht_episode_for_episode(tmp_path):
    loop, wrapped = plain_loop(PPO, SEEDS)
    assert wrapped[:len(ACROSS_THE_WRAP)] == [True] * len(ACROSS_THE_WRAP)  # the seeds do cross the wrap
    assert_same_episodes(loop, eval_rows(PPO, SEEDS, tmp_path))
    assert all(ok for ok, *_ in loop)  # and it solves them, as it solves them in training's convention


def test_the_committed_dagger_student_in_a_plain_gym_pusht_loop_is_eval_on_gym_pusht_episode_for_episode(tmp_path):
    seeds = [SEEDS[0], SEEDS[1], SEEDS[-1]]  # two across the wrap, one not
    loop, _ = plain_loop(DAGGER, seeds)
    assert_same_episodes(loop, eval_rows(DAGGER, seeds, tmp_path))
    assert sum(ok for ok, *_ in loop) >= 2


@pytest.mark.slow  # a 1024 x 3 student and its image reader a step on the CPU, gym-pusht rendering: ~15 s a policy
@pytest.mark.parametrize("seed", [0, 1])
def test_a_committed_pixel_policy_in_a_plain_gym_pusht_loop_is_eval_on_gym_pusht_episode_for_episode(seed, tmp_path):
    # gym-pusht renders the 96 x 96 image the student reads, in the loop and in the backend alike
    seeds = [SEEDS[1], SEEDS[-1]]
    loop, _ = plain_loop(PIXELS.format(seed), seeds)
    assert_same_episodes(loop, eval_rows(PIXELS.format(seed), seeds, tmp_path))
    assert any(ok for ok, *_ in loop)


def test_the_yaw_a_controller_is_handed_lies_in_the_tasks_window_however_gym_pusht_wraps_it():
    from mjx_pusht.task.gym_pusht_obs import controller_obs

    env = gym.make("gym_pusht/PushT-v0", obs_type="state")
    rng = np.random.default_rng(0)
    seen, body = [], []
    for seed in range(40):
        obs, _ = env.reset(seed=seed)
        for _ in range(3):  # and after a few pushes, the block turned
            obs, *_ = env.step(rng.uniform(0, 512, 2))
        seen.append(obs)
        body.append(env.unwrapped.block.angle)
    yaw = controller_obs(np.array(seen), "state")["state"][:, 4]
    centre = TASKS["gym-pusht"].yaw_centre
    assert ((yaw > centre - math.pi) & (yaw <= centre + math.pi)).all()
    # the block's own angle, unwrapped, gives the same yaw (gym-pusht's yaw is pi/4 minus its angle)
    assert yaw == pytest.approx(yaw_in_window(math.pi / 4 - np.array(body), centre), abs=1e-9)
    assert any(a < 0 for a in body)  # some starts lie across gym-pusht's wrap


@pytest.mark.parametrize("policy", ["ppo", "dagger"])
def test_a_policy_acts_alike_on_yaws_two_pi_apart(policy):
    from mjx_pusht.task.controllers import seed_key
    from mjx_pusht.task.rules import observe
    from mjx_pusht.train.policy import load_policy

    ctrl = load_policy(f"policy:{PPO if policy == 'ppo' else DAGGER}")
    rng = np.random.default_rng(1)
    n = 64
    pusher, tee = rng.uniform(-0.2, 0.2, (n, 2)), np.c_[rng.uniform(-0.2, 0.2, (n, 2)), rng.uniform(-3, 3, n)]
    key = seed_key(np.arange(n))
    carry = ctrl.init(key)
    acts = [ctrl.act(carry, observe(pusher, tee + [0, 0, 2 * math.pi * k]), 0, key)[0] for k in (-2, -1, 0, 1)]
    for a in acts[1:]:
        assert a == pytest.approx(acts[0], abs=1e-5)


@pytest.mark.parametrize("obs", [np.full(5, np.nan), np.array([1, 2, 3, 4, np.inf]), None, "state", np.zeros(8),
                                 np.zeros(5, complex), np.zeros((2, 5)),
                                 {"pixels": np.zeros((96, 96, 3), np.uint8), "agent_pos": np.zeros(2)}])
def test_the_policy_refuses_an_observation_it_cannot_read_in_one_line_never_nan(obs):
    from mjx_pusht.errors import MjxPushtError
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    with pytest.raises(MjxPushtError) as e:
        GymPushtPolicy(PPO)(obs)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("seed", [-1, "x", 2**63, 1.5])
def test_the_policy_refuses_a_seed_that_is_not_an_episodes(seed):
    from mjx_pusht.errors import MjxPushtError
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    with pytest.raises(MjxPushtError, match="seed must be an integer"):
        GymPushtPolicy(PPO, seed=seed)
    with pytest.raises(MjxPushtError, match="seed must be an integer"):
        GymPushtPolicy(PPO).reset(seed=seed)
