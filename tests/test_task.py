"""The PushT task, closed loop: the environment API, the controllers, the expert, and evaluation."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from mjx_pusht.cli.commands import main
from mjx_pusht.task.controllers import Expert, FromFunction, Nudge, Random, Zero, seed_key, uniform_hash
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.task.episode import Episode
from mjx_pusht.study.stats import wilson
from mjx_pusht.io.outputs import read_table
from mjx_pusht.task.reset import CLEARANCE, PUSHER_RADIUS, start_poses
from mjx_pusht.backends.results import COLUMNS
from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.rules import SUCCESS_COVERAGE, coverage, keypoints

EPISODE = Episode()  # 10 Hz control, 300 steps


@pytest.fixture(scope="session")
def expert_cpu():
    """The expert on the CPU reference: task seeds 0..15 and chapter seeds 0..7."""
    return {
        reset: run_cpu(Scenario(reset=reset, controller=Expert(), episode=EPISODE), np.arange(n))
        for reset, n in (("task", 16), ("chapter", 8))
    }


# --- the expert ---------------------------------------------------------------------------------
def test_expert_solves_every_chapter_start(expert_cpu):
    r = expert_cpu["chapter"]
    assert r.episode["success"].all()
    assert (r.episode["coverage"] >= SUCCESS_COVERAGE).all()
    # the episode's end pose is the one that was scored, and it scores as covered
    np.testing.assert_allclose(coverage(r.final), r.episode["coverage"], atol=1e-12)


def test_expert_solves_random_task_starts_and_keeps_the_t_rigid(expert_cpu):
    r = expert_cpu["task"]
    assert r.episode["success"].mean() >= 15 / 16
    ok = r.episode["success"]
    assert (r.episode["steps_to_success"][ok] >= 1).all() and (r.episode["steps_to_success"][ok] <= 300).all()
    assert r.rigid.all() and r.finite.all() and r.contained.all()
    # it moved the T: task starts lie anywhere in the workspace, far from the target
    assert np.median(np.hypot(r.start[:, 0], r.start[:, 1])) > 0.1


def test_zero_succeeds_only_where_the_start_is_already_covered():
    seeds = np.arange(24)
    r = run_cpu(Scenario(reset="task", controller=Zero(), episode=Episode(max_steps=20)), seeds)
    starts = start_poses(seeds, reset="task")
    np.testing.assert_array_equal(r.episode["success"], coverage(starts[:, :3]) >= SUCCESS_COVERAGE)
    np.testing.assert_allclose(r.final, r.start, atol=1e-9)  # nothing touches the T: it does not move


def test_random_pushing_does_not_solve_the_task():
    r = run_cpu(Scenario(reset="task", controller=Random(), episode=Episode(max_steps=100)), np.arange(16))
    assert r.episode["success"].sum() == 0
    assert r.finite.all() and r.contained.all()


def test_random_is_seeded_and_the_same_in_numpy_and_jax():
    import jax.numpy as jnp

    key = seed_key(np.array([0, 1, 2**40 + 3, 2**63 - 1]))
    a = uniform_hash(key, 7, 0)
    b = np.asarray(uniform_hash(jnp.asarray(key), jnp.int32(7), 0))
    np.testing.assert_array_equal(a, b)
    assert len(set(a.tolist())) == 4 and (a >= 0).all() and (a < 1).all()
    assert not np.array_equal(uniform_hash(key, 8, 0), a)


# --- the environment API ------------------------------------------------------------------------
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


@pytest.mark.parametrize("reset", ["chapter", "task"])
def test_start_poses_are_each_seeds_own_generator_bit_for_bit(reset):
    from mjx_pusht.task.reset import start_state

    rng = np.random.default_rng(2026)
    seeds = np.concatenate([[0, 1, 2**32 - 1, 2**32, 2**32 + 1, 2**63 - 1], rng.integers(0, 2**63 - 1, 300),
                            rng.integers(0, 2**32, 100)])
    batch = start_poses(seeds, reset=reset)
    one_by_one = np.array([start_state(int(s), reset) for s in seeds])[:, : batch.shape[1]]
    np.testing.assert_array_equal(batch, one_by_one)


def test_reset_is_per_seed_and_task_starts_are_clear():
    a = start_poses(np.array([5, 9, 11]), reset="task")
    b = start_poses(np.array([9]), reset="task")
    np.testing.assert_array_equal(a[1], b[0])
    many = start_poses(np.arange(500), reset="task")
    assert np.abs(many[:, :2]).max() < 0.39 - 0.106  # every point of the T inside the walls
    assert np.abs(many[:, 3:5]).max() < 0.39 - PUSHER_RADIUS
    # independent check that the pusher is clear of the T: sample the T's area densely
    for tee, pusher in zip(many[:50, :3], many[:50, 3:5]):
        u, v = np.meshgrid(np.linspace(-0.06, 0.06, 49), np.linspace(-0.015, 0.015, 13))
        pts = [np.column_stack([u.ravel(), v.ravel()])]
        u, v = np.meshgrid(np.linspace(-0.015, 0.015, 13), np.linspace(-0.105, -0.015, 37))
        pts.append(np.column_stack([u.ravel(), v.ravel()]))
        local = np.concatenate(pts)
        c, s = np.cos(tee[2]), np.sin(tee[2])
        world = local @ np.array([[c, s], [-s, c]]) + tee[:2]
        assert np.hypot(*(world - pusher).T).min() > PUSHER_RADIUS + CLEARANCE - 1e-3
    assert np.abs(many[:, 2]).max() > 3.0  # any yaw


def test_an_episode_that_starts_covered_terminates_at_once():
    env = PushTEnv(backend="cpu")
    s = env.reset_to([[0.0, 0.0, 0.0, 0.2, 0.2], [0.1, 0.1, 0.0, 0.2, -0.2]])
    assert s.terminated.tolist() == [True, False]
    s2 = env.step(s, np.full((2, 2), 0.5))
    assert s2.reward[0] == 0.0 and s2.metrics["return"][0] == 0.0 and s2.step[0] == 0
    assert s2.step[1] == 1
    np.testing.assert_array_equal(s2.obs["state"][0], s.obs["state"][0])  # an ended episode holds still


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
class _NudgeWithoutShortcut(FromFunction):
    """The nudge as a feedback controller, so the CPU steps it one MjData per seed."""


def test_feedback_stepping_equals_the_open_loop_rollout_to_the_bit():
    seeds = np.arange(4)
    ep = Episode(frame_skip=10, max_steps=16, terminate=False)
    nudge = Nudge(frame_skip=10)
    fb = _NudgeWithoutShortcut(name="nudge-fb", fn=lambda obs, t: nudge.act(0, obs, t, None)[0])
    a = run_cpu(Scenario(reset="chapter", controller=nudge, episode=ep), seeds)
    b = run_cpu(Scenario(reset="chapter", controller=fb, episode=ep), seeds)
    for f in ("final", "settled", "pusher_final", "gap_max_dev", "gap_settled"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))


def test_eval_with_the_nudge_gives_the_sweeps_rows(tmp_path):
    sweep, ev = tmp_path / "sweep", tmp_path / "eval"
    common = ["--seeds", "6", "--backend", "cpu", "--no-rerun", "--no-progress"]
    assert main(["sweep", *common, "--out", str(sweep)]) == 0
    assert main(["eval", *common, "--controller", "nudge", "--reset", "chapter", "--max-steps", "16",
                 "--out", str(ev)]) == 0
    a, b = read_table(sweep / "per_seed.parquet"), read_table(ev / "per_episode.parquet")
    for col in COLUMNS:
        np.testing.assert_array_equal(a[col], b[col], err_msg=col)


# --- eval ----------------------------------------------------------------------------------------
def test_wilson_interval_matches_the_closed_form():
    z = 1.959964
    assert wilson(0, 100)[0] == 0.0 and wilson(0, 100)[1] == pytest.approx(z * z / (100 + z * z))
    lo, hi = wilson(50, 100)
    assert lo == pytest.approx(0.4038, abs=1e-4) and hi == pytest.approx(0.5962, abs=1e-4)


def test_eval_writes_episodes_summary_and_recording(tmp_path):
    out = tmp_path / "eval"
    assert main(["eval", "--seeds", "4", "--reset", "chapter", "--backend", "cpu", "--out", str(out),
                 "--no-progress", "--record", "2"]) == 0
    table = read_table(out / "per_episode.parquet")
    assert table["success"].all() and (table["final_coverage"] >= 0.95).all()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success_rate"] == 1.0 and summary["success_rate_ci95"][1] == 1.0
    assert summary["success_rate_ci95"][0] == pytest.approx(wilson(4, 4)[0])
    from test_record import _contents, _views

    views = _views(out / "eval.rrd")
    assert views["/plots/coverage"]["range"] == [0.0, 1.05] and "0.95" in views["/plots/coverage"]["display_name"]
    entities, timelines = _contents(out / "eval.rrd")
    assert {"/plots/coverage/seed_0", "/plots/reward/seed_1", "/world/seed_0/objects/tee"} <= entities
    assert "sim_time" in timelines


ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def _cli(*args, cwd=None, env=None):
    return subprocess.run([sys.executable, "-m", "mjx_pusht", *args], capture_output=True, text=True,
                          cwd=cwd, env=env or ENV)


def test_a_users_controller_by_dotted_path_and_bad_controllers_fail_in_one_line(tmp_path):
    (tmp_path / "my_policy.py").write_text(
        "def hold(obs, t):\n    return obs['state'][..., 0:2] * 0.0\n"
        "def wrong(obs, t):\n    return obs['state']\n")
    (tmp_path / "broken_policy.py").write_text("import nonexistent_package_xyz\n")
    env = {**ENV, "PYTHONPATH": str(tmp_path) + os.pathsep + ENV.get("PYTHONPATH", "")}
    base = ["eval", "--seeds", "2", "--backend", "cpu", "--max-steps", "3", "--no-rerun", "--no-progress"]
    ok = _cli(*base, "--controller", "my_policy:hold", "--out", str(tmp_path / "ok"), env=env)
    assert ok.returncode == 0, ok.stderr
    assert read_table(tmp_path / "ok" / "per_episode.parquet")["episode_length"].tolist() == [3, 3]
    for spec, words in (("teleport", "unknown controller"), ("broken_policy:hold", "cannot import"),
                        ("my_policy:missing", "no function"), ("my_policy:wrong", "shape")):
        r = _cli(*base, "--controller", spec, "--out", str(tmp_path / "bad"), env=env)
        assert r.returncode != 0 and words in r.stderr, (spec, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr


def test_eval_sweeps_parameters_as_sweep_does(tmp_path):
    out = tmp_path / "kv"
    assert main(["eval", "--seeds", "2", "--reset", "chapter", "--backend", "cpu", "--max-steps", "60",
                 "--param", "kv=10,20", "--out", str(out), "--no-rerun", "--no-progress"]) == 0
    t = read_table(out / "per_episode.parquet")
    assert t["param_kv"].tolist() == [10.0, 10.0, 20.0, 20.0] and t["seed"].tolist() == [0, 1, 0, 1]
    # kv 20 is the authored scene: those rows are the plain evaluation's
    plain = run_cpu(Scenario(reset="chapter", controller=Expert(), episode=Episode(max_steps=60)), np.arange(2))
    np.testing.assert_array_equal(t["final_coverage"][2:], plain.episode["coverage"])


def test_bad_eval_input_is_one_line(tmp_path, capsys):
    for argv in (["eval", "--max-steps", "0"], ["eval", "--reset", "anywhere"], ["eval", "--frame-skip", "-1"],
                 ["eval", "--controller", "random", "--action", "position"]):
        assert main([*argv, "--out", str(tmp_path)]) != 0
        err = capsys.readouterr().err.strip()
        assert err.startswith("mjx-pusht: error:") and len(err.splitlines()) == 1, err


# --- MJX: the controller runs inside the compiled scan -----------------------------------------
def test_mjx_jax_runs_the_expert_in_the_scan_and_solves_the_chapter_starts():
    from mjx_pusht.backends.base import MjxBackend

    sc = Scenario(reset="chapter", controller=Expert(), episode=Episode(max_steps=120))
    backend = MjxBackend(sc, "jax")
    r = backend.run(np.arange(4))
    assert r.episode["success"].all() and r.rigid.all()
    compiled = backend.compile_seconds
    again = backend.run(np.arange(4, 7), batch=4)  # another chunk of the same batch shape: no second compile
    assert backend.compile_seconds == compiled and len(backend.runner._fns) == 1
    assert again.episode["success"].all()


@pytest.mark.warp
def test_mjx_warp_runs_the_expert_in_the_scan_and_agrees_with_the_cpu():
    from mjx_pusht.backends.base import MjxBackend
    from mjx_pusht.backends.mjx import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    sc = Scenario(reset="chapter", controller=Expert(), episode=Episode(max_steps=80))
    r = MjxBackend(sc, "warp").run(np.arange(2))
    c = run_cpu(sc, np.arange(2))
    assert r.episode["success"].tolist() == c.episode["success"].tolist() == [True, True]
    assert np.abs(r.episode["steps_to_success"] - c.episode["steps_to_success"]).max() <= 3


@pytest.mark.warp
def test_eval_on_mjx_warp_through_the_cli_matches_the_cpu_verdicts(tmp_path):
    from mjx_pusht.backends.mjx import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    common = ["--seeds", "2", "--reset", "chapter", "--max-steps", "80", "--no-rerun", "--no-progress"]
    assert main(["eval", *common, "--backend", "mjx-warp", "--out", str(tmp_path / "w")]) == 0
    assert main(["eval", *common, "--backend", "cpu", "--out", str(tmp_path / "c")]) == 0
    w, c = read_table(tmp_path / "w" / "per_episode.parquet"), read_table(tmp_path / "c" / "per_episode.parquet")
    assert w["success"].tolist() == c["success"].tolist() == [True, True]
    summary = json.loads((tmp_path / "w" / "summary.json").read_text())
    assert summary["backend"] == "mjx-warp" and "primitive box_box" in summary["collision_functions"]["box-box"]
