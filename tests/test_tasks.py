"""The tasks (task/tasks.py) and gym-pusht itself as a backend (backends/gym_pusht.py).

The gym-pusht backend is checked against gym-pusht's own env driven by a plain loop written here, the way a
gym-pusht user writes it: its observations in, its pixel targets out, its `info` read back."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mjx_pusht import make_backend
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.evaluate import evaluate
from mjx_pusht.task.reset import start_poses
from mjx_pusht.task.tasks import LEAD, TASKS, get

gym_pusht = pytest.importorskip("gym_pusht")  # a test extra: pip install 'mjx-pusht[test]'

SEEDS = np.array([3, 11, 12, 40])
STEPS = 40


def sweep_targets(obs, t):
    """A user's controller in the world frame (metres): circle the goal at 12 cm, half a turn in 40 steps, so the
    pusher sweeps through the arena's middle, meeting the T on some seeds. An open loop in t: both runs get the same
    targets to the bit, whatever their states."""
    a = math.pi * t / STEPS
    return np.broadcast_to(np.array([0.12 * math.cos(a), 0.12 * math.sin(a)]), obs["state"].shape[:-1] + (2,))


def plain_gym_pusht_loop(seed: int, steps: int) -> dict:
    """gym-pusht's own env, as its users drive it: targets in pixels, success and coverage from its info."""
    from gym_pusht.envs.pusht import PushTEnv

    env = PushTEnv(obs_type="state")
    env.reset(seed=seed)
    out = {"success": False, "steps_to_success": -1, "length": 0, "best": 0.0}
    for t in range(steps):
        target = frame.to_px(sweep_targets({"state": np.zeros((1, 5))}, t))[0]
        # gym-pusht's action space is float32: its action, as a user's loop (and GymPushtPolicy) sends it
        obs, _, terminated, _, info = env.step(np.clip(target, 0, 512).astype(np.float32))
        out["length"], out["coverage"], out["best"] = t + 1, info["coverage"], max(out["best"], info["coverage"])
        if info["is_success"] and not out["success"]:
            out["success"], out["steps_to_success"] = True, t + 1
        if terminated:
            break
    out["block"] = obs[2:5]
    return out


def test_the_two_tasks_are_data_the_one_control_step_reads():
    chapter, gym = TASKS["chapter"], TASKS["gym-pusht"]
    assert (chapter.variant, chapter.reset, chapter.action_type) == ("chapter", "task", "velocity")
    assert (gym.variant, gym.reset, gym.action_type) == ("gym-pusht", "gym-pusht", "target")
    assert chapter.episode().end_covered_start and not gym.episode().end_covered_start
    assert gym.episode().success == 0.95 and gym.episode().max_steps == 300  # gym-pusht's rule and its TimeLimit
    with pytest.raises(MjxPushtError, match="unknown task"):
        get("pusht-v9")
    with pytest.raises(MjxPushtError, match="starts from gym-pusht"):
        gym.check_reset("chapter")


def test_a_velocity_controller_commands_the_target_gym_pushts_pd_law_settles_to_at_that_velocity():
    """... within gym-pusht's action space, its 512-pixel frame: a target past its edge is clipped there, as gym-pusht
    (its backend, the drop-in, LeRobot) clips its actions."""
    from mjx_pusht.task.controllers import Random

    ctrl = TASKS["gym-pusht"].controller("random")
    assert ctrl.action_type == "target"
    key = np.zeros((1, 2), np.uint32)
    for pusher in ([0.0, 0.015], [0.1, -0.2]):  # the frame's centre; 3 cm inside its edge, the target 9 cm past it
        obs = {"state": np.array([pusher + [0.0, 0.0, 0.3]])}
        target, _ = ctrl.act(ctrl.init(key), obs, 5, key)
        velocity, _ = Random().act(None, obs, 5, key)
        lead = obs["state"][:, 0:2] + 0.2 * velocity  # kv / kp = 20 / 100 s
        np.testing.assert_allclose(frame.to_px(target), np.clip(frame.to_px(lead), 0, 512), atol=1e-9)
        assert np.array_equal(target, lead) == (pusher == [0.0, 0.015])
    assert LEAD == 0.2


def test_the_gym_pusht_backend_is_gym_pushts_own_env_under_the_same_targets():
    task = get("gym-pusht")
    from mjx_pusht.task.controllers import FromFunction

    sc = Scenario(task.scene(), reset=task.reset, episode=task.episode(max_steps=STEPS),
                  controller=FromFunction(name="sweep", action_type="target", fn=sweep_targets))
    backend = make_backend("gym-pusht", sc)
    r = backend.run(SEEDS, poses=start_poses(SEEDS, reset="gym-pusht"))
    backend.close()
    moved = 0
    for i, seed in enumerate(SEEDS):
        ref = plain_gym_pusht_loop(int(seed), STEPS)
        assert bool(r.episode["success"][i]) == ref["success"]
        assert r.episode["steps_to_success"][i] == ref["steps_to_success"]
        assert r.episode["length"][i] == ref["length"]
        assert r.episode["coverage"][i] == ref["coverage"] and r.episode["best_coverage"][i] == ref["best"]
        origin, angle = frame.pose_to_px(r.final[i : i + 1])
        np.testing.assert_allclose(origin[0], ref["block"][:2], atol=1e-9)
        assert abs((angle[0] - ref["block"][2] + math.pi) % (2 * math.pi) - math.pi) < 1e-9
        moved += not np.allclose(r.final[i], r.start[i])
    assert moved >= 1  # the sweep met the T: the comparison covered contact, not only a pusher in free space


def test_eval_runs_gym_pushts_task_on_the_drop_in_and_on_gym_pusht_from_the_same_starts(tmp_path):
    runs = {b: evaluate("zero", SEEDS, tmp_path / b, backend=b, task="gym-pusht", max_steps=3, rerun=False,
                        progress=False) for b in ("cpu", "gym-pusht")}
    for b, s in runs.items():
        assert s["config"]["task"] == "gym-pusht" and s["config"]["reset"] == "gym-pusht" and s["backend"] == b
    from mjx_pusht.io.outputs import read_table

    cpu, gym = (read_table(tmp_path / b / "per_episode.parquet") for b in ("cpu", "gym-pusht"))
    for col in ("start_x", "start_y", "start_yaw", "pusher_start_x", "pusher_start_y"):
        np.testing.assert_allclose(cpu[col], gym[col], atol=1e-12)
    # a pusher that holds still leaves the T where it started in both
    np.testing.assert_allclose(gym["tee_final_x"], gym["start_x"], atol=1e-12)


def test_the_gym_pusht_backend_runs_gym_pushts_task_only():
    with pytest.raises(MjxPushtError, match="gym-pusht's task only"):
        make_backend("gym-pusht", Scenario(TASKS["chapter"].scene(), reset="task",
                                           controller=TASKS["chapter"].controller("zero")))


@pytest.mark.parametrize(("extra", "why"), [
    (("--algo", "ppo", "--backend", "mjx-jax", "--goal", "random"), "--goal random trains a goal-conditioned policy "
     "with DAgger"),  # not: "--teacher" unasked (PPO trains on gym-pusht's task, at its fixed goal)
    (("--backend", "gym-pusht"), "train rolls out on cpu, mjx-jax or mjx-warp"),  # before the banner, not after
])
def test_train_refuses_on_gym_pushts_task_what_it_cannot_do_in_one_line(extra, why, tmp_path, capsys):
    from mjx_pusht.cli import main

    assert main(["train", "--task", "gym-pusht", *extra, "--no-rerun", "--out", str(tmp_path / "t")]) == 1
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"mjx-pusht: error: {why}"), captured.err
    assert captured.out == "" and not (tmp_path / "t").exists()


def test_the_functional_env_of_gym_pushts_task_starts_and_ends_episodes_as_gym_pusht_does():
    from gym_pusht.envs.pusht import PushTEnv as Theirs

    from mjx_pusht.envs.functional import PushTEnv

    env = PushTEnv.for_task("gym-pusht")
    assert (env.reset_kind, env.action_type, env.episode.max_steps) == ("gym-pusht", "target", 300)
    s = env.reset(SEEDS)
    for i, seed in enumerate(SEEDS):
        theirs = Theirs(obs_type="state")
        obs, _ = theirs.reset(seed=int(seed))
        np.testing.assert_allclose(frame.to_px(s.obs["state"][i : i + 1, 0:2])[0], obs[0:2], atol=1e-9)
        origin, _ = frame.pose_to_px(s.obs["state"][i : i + 1, 2:5])
        np.testing.assert_allclose(origin[0], obs[2:4], atol=1e-9)


def small_policy(path, obs_type: str = "state"):
    """A small untrained student of gym-pusht's task, written as `train --task gym-pusht` writes one."""
    import jax
    import jax.numpy as jnp

    from mjx_pusht.train.policy import feature_size, network, save

    fmt = TASKS["gym-pusht"].memory
    width = feature_size(obs_type, fmt)
    params = network((32,), "relu", 0, 2 + fmt.size).init(jax.random.key(3), jnp.zeros((1, width)))["params"]
    save(path, params, {"obs_type": obs_type, "activation": "relu", "in_mean": [0.0] * width, "in_std": [0.1] * width,
                        "method": "dagger", "config": {"task": "gym-pusht"}, "memory": fmt.meta()})
    return path


def test_a_policy_of_the_chapter_task_is_refused_as_a_gym_pusht_controller(tmp_path):
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy
    from mjx_pusht.train.policy import load_checkpoint, save

    path = small_policy(tmp_path / "p.msgpack")
    params, meta = load_checkpoint(path)
    save(tmp_path / "chapter.msgpack", params, {**meta, "config": {}})
    with pytest.raises(MjxPushtError, match="trained on the chapter task"):
        GymPushtPolicy(tmp_path / "chapter.msgpack")


def test_a_dagger_student_decodes_its_memory_in_the_format_its_features_encode():
    from mjx_pusht.task.memory import CarryFormat
    from mjx_pusht.train.dagger import DaggerConfig, student_meta

    for cfg in (DaggerConfig(), DaggerConfig(task="gym-pusht", reset="gym-pusht", teacher="expert")):
        assert CarryFormat.of(student_meta(cfg, (0.0, 1.0))) == cfg.memory
    assert TASKS["gym-pusht"].memory.moves == len(__import__("mjx_pusht.task.expert_gym_pusht",
                                                             fromlist=["CONTACTS"]).CONTACTS) + 1


@pytest.mark.slow
def test_daggers_judgement_of_a_gym_pusht_student_is_evals_of_its_checkpoint(tmp_path):
    """The held-out judgement inside training and `eval` of the written policy are the same episodes (MuJoCo C,
    float64): a student that read its memory otherwise in training than its checkpoint does (two H100 runs did)
    is judged at one rate and evaluated at another."""
    import json

    from helpers import cli

    out = tmp_path / "run"
    r = cli("train", "--task", "gym-pusht", "--backend", "cpu", "--envs", "32", "--eval-envs", "32", "--iterations",
            "2", "--fit-steps", "200", "--no-rerun", "--no-progress", "--out", str(out))
    assert r.returncode == 0, r.stderr
    last = (out / "curve.csv").read_text().splitlines()[-1].split(",")
    header = (out / "curve.csv").read_text().splitlines()[0].split(",")
    judged = float(last[header.index("coverage")])
    evaluated = json.loads((out / "eval" / "summary.json").read_text())["final_coverage"]["mean"]
    # (curve.csv keeps 7 digits); the student moved the T
    assert judged == pytest.approx(evaluated, abs=1e-6) and evaluated > 0.02


def nan_targets(obs, t):
    return np.full(obs["state"].shape[:-1] + (2,), np.nan if t == 2 else 0.0)


def test_a_non_finite_action_in_gym_pusht_is_the_controllers_error_naming_seeds_and_step():
    from mjx_pusht.task.controllers import FromFunction

    task = get("gym-pusht")
    sc = Scenario(task.scene(), reset=task.reset, episode=task.episode(max_steps=5),
                  controller=FromFunction(name="nan", action_type="target", fn=nan_targets))
    from mjx_pusht.backends.gym_pusht import episodes

    with pytest.raises(MjxPushtError, match=r"non-finite action at step 2 for seeds \[3, 11\]"):
        episodes(sc, np.array([3, 11]))
