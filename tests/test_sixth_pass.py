"""The sixth hostile pass's findings, each run again as written (docs/notebook/hostile6.md; what changed for each:
docs/notebook/boundary.md, "After the sixth pass")."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest
from fuzzing import snapshot
from helpers import ENV, RUNS, one_line, over

import mjx_pusht
from mjx_pusht import Scenario, make_backend
from mjx_pusht.boundary import BYTES_PER_CPU_ENV, available_memory
from mjx_pusht.cli import main
from mjx_pusht.errors import ConfigError

VIDEO = [*RUNS["eval"], "--video-size", "32", "--video-episodes", "2"]


def test_eval_video_replace_never_overwrites_a_file_no_run_wrote(tmp_path, capsys):
    """LOST 1: `--video USERFILE --replace` overwrote the user's keep.gif; --replace now overwrites only the video
    this command's earlier run into the same --out wrote (its summary names the file and its hash)."""
    keep = tmp_path / "keep.gif"
    keep.write_bytes(b"GIF89a a user's own picture")
    for extra in ([], ["--replace"]):
        assert main([*VIDEO, "--video", str(keep), "--out", str(tmp_path / "o"), *extra]) == 1
        one_line(capsys, f"--video {keep} already exists")
        assert keep.read_bytes() == b"GIF89a a user's own picture" and sorted(os.listdir(tmp_path)) == ["keep.gif"]
    # the eval's own video, rerun into the same --out, is replaced; into another --out, it is another run's: refused
    own = tmp_path / "own.gif"
    assert main([*VIDEO, "--video", str(own), "--out", str(tmp_path / "o")]) == 0, capsys.readouterr().err
    first = own.read_bytes()
    assert first[:6] == b"GIF89a"
    assert main([*VIDEO, "--video", str(own), "--out", str(tmp_path / "o")]) == 1
    one_line(capsys, "already exists", "--replace")
    assert main([*VIDEO, "--video", str(own), "--out", str(tmp_path / "o2"), "--replace"]) == 1
    one_line(capsys, "no earlier eval into")
    assert not (tmp_path / "o2").exists()
    assert main([*VIDEO, "--video", str(own), "--out", str(tmp_path / "o"), "--replace"]) == 0, capsys.readouterr().err
    # a user's change to the video after the run makes it theirs: refused again
    own.write_bytes(first + b"edited")
    assert main([*VIDEO, "--video", str(own), "--out", str(tmp_path / "o"), "--replace"]) == 1
    one_line(capsys, "no earlier eval into")
    assert own.read_bytes() == first + b"edited"


def test_eval_video_into_another_runs_folder_is_refused(tmp_path, capsys):
    """SILENT 17: `--video fx/eval/v.gif` added a file to another eval's finished folder."""
    assert main([*RUNS["eval"], "--out", str(tmp_path / "a")]) == 0, capsys.readouterr().err
    before = snapshot(tmp_path / "a")
    for extra in ([], ["--replace"]):
        assert main([*VIDEO, "--video", str(tmp_path / "a" / "v.gif"), "--out", str(tmp_path / "b"), *extra]) == 1
        one_line(capsys, "inside another run's folder")
    assert snapshot(tmp_path / "a") == before and not (tmp_path / "b").exists()


# LOST 2: a refused run re-stamped the folder's run file, so the same refused command then went through. Each
# command: a first run, a refused second (other settings) that leaves the run file byte for byte, the same refused
# command again still refused, and the first run's results untouched.
REFUSED = {
    "demos": (RUNS["demos"], ["--seeds", "3"]),
    "sweep": (RUNS["sweep"], ["--seeds", "3"]),
    "eval": (RUNS["eval"], ["--seeds", "3"]),
    "scene": (RUNS["scene"], ["--steps", "6"]),  # SILENT 12: other settings overwrote without --replace
}


@pytest.mark.parametrize("command", sorted(REFUSED))
def test_a_refused_rerun_leaves_the_run_file_and_is_refused_again(command, tmp_path, capsys):
    base, other = REFUSED[command]
    out = str(tmp_path / "o")
    assert main([*base, "--out", out]) == 0, capsys.readouterr().err
    capsys.readouterr()
    before = snapshot(tmp_path)
    for _ in range(2):
        assert main(over(base, *other, "--out", out)) == 1
        one_line(capsys, "--replace")
        assert snapshot(tmp_path) == before
    assert main([*base, "--out", out]) == 0, capsys.readouterr().err  # the first run's own settings: its rerun


def test_scene_other_break_into_its_folder_needs_replace(tmp_path, capsys):
    """SILENT 12: `--break split-tee` into a welded scene's folder overwrote its metrics without --replace."""
    out = str(tmp_path / "o")
    assert main([*RUNS["scene"], "--steps", "5", "--out", out]) == 0
    metrics = (tmp_path / "o" / "metrics.json").read_bytes()
    assert main([*RUNS["scene"], "--steps", "5", "--break", "split-tee", "--out", out]) == 1
    one_line(capsys, "other seeds' or settings'", "--replace")
    assert (tmp_path / "o" / "metrics.json").read_bytes() == metrics
    assert main([*RUNS["scene"], "--steps", "5", "--seed", "3", "--out", out]) == 0  # another seed: documented
    assert main([*RUNS["scene"], "--steps", "5", "--break", "split-tee", "--replace", "--out", out]) == 0
    assert json.loads((tmp_path / "o" / "metrics.json").read_text())["tee_stayed_rigid"] is False


def test_replace_on_an_unfinished_same_settings_sweep_starts_it_again(tmp_path, capsys):
    """REFUSED 18: `sweep --replace` on its own unfinished chunks said "pass --resume"; the docs say --replace
    removes them. The rerun's table equals an uninterrupted run's."""
    from mjx_pusht.io.outputs import read_table

    args = over(RUNS["sweep"], "--seeds", "4", "--chunk", "2", "--out", str(tmp_path / "o"))
    assert main(args) == 0
    table = read_table(tmp_path / "o" / "per_seed.parquet")
    (tmp_path / "o" / "per_seed.parquet").unlink()
    (tmp_path / "o" / "summary.json").unlink()
    parts = tmp_path / "o" / ".parts"
    parts.mkdir()
    (parts / "manifest.json").write_text("{}")  # seeds and settings no matter: --replace drops them
    (parts / "seeds-000000000000-000000000002.parquet").write_bytes(b"a cut chunk")
    capsys.readouterr()
    assert main(args) == 1
    one_line(capsys, "pass --resume")
    assert main([*args, "--replace"]) == 0, capsys.readouterr().err
    again = read_table(tmp_path / "o" / "per_seed.parquet")
    assert not parts.exists() and all(np.array_equal(again[k], table[k], equal_nan=True) for k in table
                                      if k not in ("wall_seconds",))


def test_train_resume_with_replace_is_refused(tmp_path, capsys):
    """SILENT 11: `train --resume --replace` resumed and ignored --replace."""
    assert main([*RUNS["train"], "--resume", "--replace", "--out", str(tmp_path / "o")]) == 2  # a usage error
    one_line(capsys, "--resume", "--replace", "give one")
    assert not (tmp_path / "o").exists()


SLOW = '''import time
import numpy as np


def slow(obs, t):
    time.sleep(200)  # a user's controller busy for minutes
    return np.zeros(obs["state"].shape[:-1] + (2,))
'''


@pytest.mark.slow  # two processes started, 4 s and more each on this CPU
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_ends_an_eval_whose_controller_is_busy_within_seconds(sig, tmp_path):
    """HANG 3: SIGINT or SIGTERM to a CPU eval whose controller sleeps: no exit in 120 s (shutting its worker
    processes down waited for the controller). Now one line and 130 / 143 within seconds."""
    (tmp_path / "myctl.py").write_text(SLOW)
    env = {**ENV, "PYTHONPATH": os.pathsep.join([str(tmp_path), ENV.get("PYTHONPATH", "")])}
    p = subprocess.Popen([sys.executable, "-m", "mjx_pusht", "eval", "--backend", "cpu", "--no-rerun", "--seeds", "64", "--max-steps", "20",
                          "--no-progress", "--controller", "myctl:slow", "--out", str(tmp_path / "o")],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path,
                         preexec_fn=lambda: (signal.signal(signal.SIGINT, signal.SIG_DFL),
                                             signal.signal(signal.SIGTERM, signal.SIG_DFL)))
    time.sleep(6)  # the workers are in the controller's sleep by now
    assert p.poll() is None, p.communicate()
    t0 = time.monotonic()
    p.send_signal(sig)  # to the process only, as `kill -INT PID` sends it
    try:
        _, stderr = p.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        p.kill()
        raise AssertionError("no exit in 20 s after the signal") from None
    assert time.monotonic() - t0 < 5, time.monotonic() - t0
    assert p.returncode == 128 + sig, (p.returncode, stderr[-2000:])
    assert "Traceback" not in stderr and ("interrupted" in stderr or "terminated" in stderr), stderr[-2000:]


@pytest.mark.parametrize("make", [
    lambda: __import__("mjx_pusht.envs.functional", fromlist=["PushTEnv"]).PushTEnv.for_task("gym-pusht", bogus=1),
    lambda: gym.make("mjx_pusht/PushT-v0", bogus=1),
    lambda: gym.make("mjx_pusht/PushT-gym-pusht-v0", bogus=1),
    lambda: gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, bogus=1),
    lambda: gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=2, vectorization_mode="vector_entry_point", bogus=1),
])
def test_an_unknown_keyword_is_one_line_naming_the_known_ones(make):
    """TRACEBACK 6: a raw TypeError named only the stranger. Still a TypeError (as Python's own), and one line."""
    with pytest.raises(TypeError, match=r"got an unexpected keyword argument 'bogus'; it takes (backend|.*obs_type)") \
            as e:
        make()
    assert isinstance(e.value, ConfigError) and "\n" not in str(e.value)


@pytest.fixture(scope="module")
def nudge():
    from mjx_pusht.task.schedule import Schedule

    return make_backend("cpu", Scenario(schedule=Schedule(nudge_steps=3)))


@pytest.mark.parametrize("options,words", [
    ({"combos": 5}, "combos must have shape (2,)"),
    ({"combos": [0, 3]}, "combos must index the scenario's 1 parameter combinations"),
    ({"poses": np.zeros((5, 5))}, "poses must have shape (2, 3)"),  # a NumPy broadcast error
    ({"poses": np.zeros((2, 5))}, "poses must have shape (2, 3)"),  # the chapter's starts: the tee's (x, y, yaw)
    ({"poses": np.full((2, 3), np.nan)}, "poses must be finite"),  # was stepped into MuJoCo
    ({"batch": "x"}, "batch must be an integer"),
    ({"batch": 0}, "batch must be an integer"),
    ({"batch": -1}, "batch must be an integer"),
])
def test_backend_run_options_are_checked_before_mujoco_runs(nudge, options, words, tmp_path, monkeypatch):
    """TRACEBACK 7 and SILENT 13: IndexError, NumPy broadcast errors, or runs with the option misread; a NaN start
    wrote MUJOCO_LOG.TXT into the caller's folder."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=re.escape(words)):
        nudge.run(np.arange(2), **options)
    assert os.listdir(tmp_path) == []


def test_backend_run_options_that_are_right_give_the_rows_of_the_default(nudge):
    """The check takes what was right: poses given as the seeds' own starts equal the run without them."""
    from mjx_pusht.task.reset import start_poses

    seeds = np.arange(3)
    a = nudge.run(seeds)
    b = nudge.run(seeds, combos=np.zeros(3, np.int64), batch=2, poses=start_poses(seeds, reset=nudge.scenario.reset))
    assert np.array_equal(a.final, b.final)


def test_functional_env_and_autoreset_refuse_none():
    """TRACEBACK 8: AttributeError tracebacks (`AutoReset(None)` only at its first reset)."""
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.envs.wrappers import AutoReset

    with pytest.raises(ConfigError, match="state must be a State"):
        PushTEnv().check(None)
    with pytest.raises(ConfigError, match="AutoReset's env must be a functional PushTEnv"):
        AutoReset(None)


@pytest.mark.parametrize("call,words", [
    (lambda: mjx_pusht.start_pose(-1), "seed must be an integer from 0 to 2**63-1"),
    (lambda: mjx_pusht.start_pose("x"), "seed must be an integer"),
    (lambda: mjx_pusht.start_pose(1.5), "seed must be an integer"),
    (lambda: mjx_pusht.start_pose(np.nan), "seed must be an integer"),
    (lambda: mjx_pusht.start_pose(None), "got None"),  # SILENT 15: fresh OS entropy, another pose each call
    (lambda: mjx_pusht.start_pose(2**64), "seed must be an integer"),  # SILENT 15
    (lambda: mjx_pusht.start_poses("ab"), "seeds must be integers"),
    (lambda: mjx_pusht.start_poses(None), "seeds must be integers"),
    (lambda: mjx_pusht.start_poses([[0, 1]]), "seeds must be integers"),  # SILENT 15: 2-D
    (lambda: mjx_pusht.start_poses([0.5]), "seeds must be integers"),  # SILENT 15: fractional
    (lambda: mjx_pusht.build_model(None), "spec must be a SceneSpec"),
    (lambda: mjx_pusht.build_model("split-tee"), "spec must be a SceneSpec"),
    (lambda: mjx_pusht.scene_xml("x"), "spec must be a SceneSpec"),
    (lambda: mjx_pusht.check_tree(mjx_pusht.build_model(mjx_pusht.SceneSpec()), "bogus"), "unknown break_it"),
    (lambda: mjx_pusht.check_tree(None, "none"), "model must be a compiled mujoco.MjModel"),
    (lambda: mjx_pusht.read_tree(None), "model must be a compiled mujoco.MjModel"),
    (lambda: mjx_pusht.weld_gap(np.zeros(2), np.zeros(3)), "positions of one shape"),
    (lambda: mjx_pusht.gap_deviation(np.zeros((2, 3)), np.zeros((3, 3))), "positions of one shape"),
    (lambda: mjx_pusht.weld_gap("a", "b"), "must be real numbers"),
    (lambda: mjx_pusht.stayed_rigid("x"), "must be real numbers"),
])
def test_the_exported_helpers_check_their_arguments(call, words):
    """TRACEBACK 9: NumPy's, MuJoCo's or a dict's tracebacks from the helpers `import mjx_pusht` exports."""
    with pytest.raises(ConfigError, match=re.escape(words)):
        call()


def test_the_exported_helpers_still_compute_what_they_did():
    """Against an independent computation: the pose NumPy's generator draws for the seed, the distance by hand."""
    from mjx_pusht.task.reset import TEE_X_RANGE, TEE_Y_RANGE, TEE_YAW_RANGE

    rng = np.random.default_rng(7)
    assert mjx_pusht.start_pose(np.int64(7)) == tuple(float(rng.uniform(*r)) for r in (TEE_X_RANGE, TEE_Y_RANGE,
                                                                                         TEE_YAW_RANGE))
    assert mjx_pusht.weld_gap([0.0, 0.0, 0.0], [0.0, 3.0, 4.0]) == 5.0
    assert mjx_pusht.stayed_rigid(np.array([0.0, np.nan])).tolist() == [True, False]  # NaN: never rigid (documented)
    assert mjx_pusht.check_tree(mjx_pusht.build_model(mjx_pusht.SceneSpec()), "none") is not None


TRAIN = ["train", "--algo", "dagger", "--backend", "cpu", "--iterations", "1", "--eval-envs", "4", "--max-steps", "5",
         "--minutes", "0.5", "--no-progress", "--no-rerun"]


@pytest.mark.parametrize("flags,per", [
    (["--envs", "4194304", "--hidden", "8"], BYTES_PER_CPU_ENV * 4194304),  # the documented maxima, each
    (["--envs", "4", "--fit-steps", "5", "--batch", "16", "--hidden", "65536,65536,65536"], 16 * 2 * 65536**2),
    (["--envs", "4", "--hidden", "8", "--max-samples", "1073741824"], 4 * 17 * 2**30),
])
def test_train_maxima_past_this_machines_memory_are_refused_before_anything_is_written(flags, per, tmp_path, capsys):
    """TRACEBACK 4: MuJoCo's 'Could not allocate memory' or XLA's RESOURCE_EXHAUSTED traceback (under a ulimit; past
    it, the kernel's OOM killer). The estimate (`per`: bytes from the sizes, a lower bound) is past this machine's."""
    if per <= available_memory():
        pytest.skip("this machine has the memory: nothing to refuse")
    assert main([*TRAIN, *flags, "--out", str(tmp_path / "o")]) == 1
    one_line(capsys, "of memory", "available")
    assert not (tmp_path / "o").exists()


def test_a_functional_reset_past_this_machines_memory_is_refused():
    """TRACEBACK 5: `PushTEnv().reset(np.arange(10**6))` was MuJoCo's FatalError (the vector env refused in one line)."""
    from mjx_pusht.envs.functional import PushTEnv

    n = 2 * available_memory() // BYTES_PER_CPU_ENV + 1
    with pytest.raises(ConfigError, match="worlds on the cpu backend needs about"):
        PushTEnv().reset(np.arange(n))


@pytest.mark.parametrize("make", [
    lambda: gym.make("mjx_pusht/PushT-v0"),
    lambda: gym.make("mjx_pusht/PushT-gym-pusht-v0"),
    lambda: gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu"),
    lambda: gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=2, backend="cpu",
                         vectorization_mode="vector_entry_point"),
])
def test_an_unknown_reset_option_is_refused_and_lerobots_is_ignored(make):
    """SILENT 14: `reset(options={'bogus': 1})` (a misspelt reset_to_state) was ignored; LeRobot's own option, which
    its eval passes on every rollout, still is (tests/test_validate.py: the same episode with it as without)."""
    env = make()
    with pytest.raises(ConfigError, match="takes no option 'bogus'"):
        env.reset(seed=0, options={"bogus": 1})
    env.reset(seed=0, options={"lerobot_new_rollout": True})
    env.close()


def test_a_fractional_start_queue_depth_is_refused():
    """SILENT 16: `make_vec(..., depth=2.5)` was taken."""
    with pytest.raises(ConfigError, match="depth"):
        gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu", depth=2.5)


SWEEP = ["sweep", "--backend", "cpu", "--no-progress", "--seeds", "2", "--steps", "5"]


@pytest.mark.parametrize("argv,words", [
    ([*SWEEP, "--no-rerun", "--record", "3"], "--no-rerun skips"),
    ([*RUNS["eval"], "--record", "2"], "--no-rerun skips"),
    ([*RUNS["train"][:-4], "--record", "2", "--no-rerun"], "--no-rerun skips"),
    ([*SWEEP, "--no-rerun", "--audit", "0.5"], "a cpu sweep is that reference"),
    ([*SWEEP, "--no-rerun", "--peer-timeout", "5"], "one process waits for none"),
    ([*RUNS["train"], "--image-batch", "32"], "a state student has none"),
])
def test_a_flag_the_command_would_not_read_is_refused(argv, words, tmp_path, capsys):
    """SILENT 11: each was accepted and ignored (cli.md: a flag the command would not read is refused)."""
    assert main([*argv, "--out", str(tmp_path / "o")]) in (1, 2)
    one_line(capsys, words)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("extra", [["--max-steps", "5"], ["--task", "gym-pusht"], ["--tolerance", "1e-6"]])
def test_compare_evals_refuses_the_settings_of_a_run(extra, tmp_path, capsys):
    """SILENT 11: with --evals, only --seeds and --controller were refused; these were ignored."""
    for name in ("a", "b"):
        assert main([*RUNS["eval"], "--out", str(tmp_path / name)]) == 0
    capsys.readouterr()
    assert main(["compare", "--evals", str(tmp_path / "a"), str(tmp_path / "b"), *extra,
                 "--out", str(tmp_path / "c")]) == 2
    one_line(capsys, "runs nothing", extra[0])
    assert not (tmp_path / "c").exists()


def test_a_bad_mujoco_gl_is_refused_before_eval_video_runs(tmp_path):
    """SILENT 10: `MUJOCO_GL=bogus eval --video` ran and wrote its results into a fresh --out, then refused."""
    r = subprocess.run([sys.executable, "-m", "mjx_pusht", *RUNS["eval"], "--video", str(tmp_path / "v.gif"),
                        "--video-size", "32", "--out", str(tmp_path / "o")], capture_output=True, text=True,
                       env={**ENV, "MUJOCO_GL": "bogus"}, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1 and "MUJOCO_GL='bogus'" in lines[0], r.stderr[-2000:]
    assert os.listdir(tmp_path) == []


def test_backend_run_of_more_seeds_than_fit_is_refused_at_once(nudge):
    """SILENT 13: `run(np.arange(10**8))` made no memory check (150 GB at the measured 1,500 bytes a seed) and was
    still running when killed at 100 s."""
    from mjx_pusht.boundary import BYTES_PER_SEED

    t = time.perf_counter()
    with pytest.raises(ConfigError, match="seeds needs about"):
        nudge.run(np.arange(2 * available_memory() // BYTES_PER_SEED + 1))
    assert time.perf_counter() - t < 5
