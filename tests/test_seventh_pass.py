"""Refusals that change nothing, found on review and by the seventh hostile pass (docs/notebook/hostile7.md; what
changed for each: docs/notebook/boundary.md, "After the seventh pass")."""

from __future__ import annotations

import os

import pytest
from fuzzing import snapshot
from helpers import RUNS, one_line, over

from mjx_pusht.cli import main
from mjx_pusht.io.outputs import OutputError, claim_out_dir, held_folders


@pytest.mark.parametrize("command", ["sweep", "eval", "train"])
def test_resume_with_replace_is_refused_before_anything_is_removed(tmp_path, capsys, command):
    """Review: `eval --seeds 4 --replace --resume` into a finished eval of 3 seeds removed the 3 seeds' results
    (--replace), then ran afresh (--resume ignored). Each flag undoes the other: refused, the folder as it was."""
    out = tmp_path / "o"
    assert main([*RUNS[command], "--out", str(out)]) == 0, capsys.readouterr().err
    capsys.readouterr()
    before = snapshot(out)
    assert main([*RUNS[command], "--out", str(out), "--resume", "--replace"]) == 2  # a usage error
    one_line(capsys, "--resume", "--replace", "give one")
    assert snapshot(out) == before


def test_a_commands_own_refusal_under_replace_removes_nothing(tmp_path):
    """Review: claim_out_dir removed the earlier results under --replace before it ran the command's own check, so a
    run its check refused had already removed what it was to replace."""
    out = tmp_path / "o"
    with held_folders():
        claim_out_dir(out, "eval", {"seeds": 3})
    (out / "summary.json").write_text("{}")
    (out / "per_episode.parquet").write_bytes(b"an earlier eval's table")
    before = snapshot(out)

    def refuse(path, same):
        assert not same  # other seeds: --replace would remove the earlier results
        raise OutputError("refused by the command's own check")

    with pytest.raises(OutputError, match="own check"), held_folders():
        claim_out_dir(out, "eval", {"seeds": 4}, replace=True, check=refuse)
    assert snapshot(out) == before


def test_a_signal_while_the_command_sets_up_its_handlers_is_one_line(monkeypatch, capsys):
    """TRACEBACK (seventh pass): SIGINT 0.3 s into `sweep` on a loaded machine was a KeyboardInterrupt traceback
    through `Thread.start`: the handler that raises was set before the SIGTERM watcher thread started, outside the
    command's try. A signal there now waits for the try, and is its one line."""
    import os
    import signal
    import threading

    started = threading.Thread.start

    def start_then_signal(self):
        if self.name == "sigterm-watch":
            os.kill(os.getpid(), signal.SIGTERM)  # handled by the command's handler, which is set by now
        started(self)

    monkeypatch.setattr(threading.Thread, "start", start_then_signal)
    assert main(["tree"]) == 128 + signal.SIGTERM
    one_line(capsys, "terminated", "before the command started")


@pytest.mark.parametrize("stop_after", [0, 2])
def test_an_interrupted_sweep_says_how_many_rows_it_kept(tmp_path, monkeypatch, capsys, stop_after):
    """Seen with the seventh pass: a sweep interrupted before its first chunk said "finished chunks are kept ...:
    rerun with --resume"; none was. Its line counts the rows the chunk files on disk hold."""
    import mjx_pusht.study.sweep as sweep_module

    real = sweep_module.run_sweep

    def cut(backend, seeds, out, **kw):  # the real sweep over the first chunks, then the interrupt
        if stop_after:
            real(backend, seeds[: 4 * stop_after], out, **{**kw, "chunk": 4})
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "run_sweep", cut)
    out = tmp_path / "o"
    assert main(over(RUNS["sweep"], "--seeds", "12", "--out", str(out))) == 130
    chunks = sorted((out / ".parts").glob("seeds-*.parquet"))
    assert len(chunks) == stop_after
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert (f"({4 * stop_after:,} rows) are kept" in err and "--resume" in err) if stop_after else (
        "no chunk was finished yet" in err and "without --resume" in err), err


def _policy_path():
    from pathlib import Path

    return Path(__file__).parent.parent / "outputs/reports/train/ppo-state-gym-pusht-h200/seed-0/policy.msgpack"


@pytest.mark.parametrize("call, needle", [
    ("Scenario(bogus=1)", "it takes scene, schedule"),
    ("SceneSpec(bogus=1)", "it takes break_it, pusher, variant"),
    ("Schedule(bogus=1)", "it takes settle_steps"),
    ("resolve()", "missing a required argument: 'name'"),
    ("make_backend()", "missing a required argument: 'name'"),
    ("start_poses([0, 1], kind='bogus')", "it takes seeds, reset"),
    ("start_pose(0, bogus=1)", "it takes seed"),
    ("scene_xml(SceneSpec(), bogus=1)", "it takes spec"),
    ("weld_gap(None)", "missing a required argument: 'stem_pos'"),
    ("AutoReset(PushTEnv(backend='cpu'), bogus=1)", "it takes env, mode"),
    ("GymPushtPolicy(POLICY, bogus=1)", "it takes path, seed"),
    ("PushTEnv.for_task('gym-pusht', reset_kind='task')", "takes reset_kind from the task"),
])
def test_a_public_call_given_the_wrong_arguments_is_one_line(call, needle):
    """TRACEBACK (seventh pass): Python's own TypeError for an unknown keyword, a missing argument or one given
    twice, on the exported constructors and helpers, the functional env's AutoReset and for_task, and
    GymPushtPolicy. Each binds its arguments at the door: one line naming what it takes."""
    import mjx_pusht
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.envs.wrappers import AutoReset
    from mjx_pusht.errors import MjxPushtError
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    names = {**{n: getattr(mjx_pusht, n) for n in mjx_pusht.__all__}, "PushTEnv": PushTEnv, "AutoReset": AutoReset,
             "GymPushtPolicy": GymPushtPolicy, "POLICY": _policy_path()}
    with pytest.raises(MjxPushtError) as e:
        eval(call, names)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_the_checked_calls_still_take_what_they_took():
    """The binding refuses only what Python would: keywords and defaults work as before."""
    import numpy as np

    import mjx_pusht
    from mjx_pusht import Scenario, SceneSpec, make_backend

    assert mjx_pusht.weld_gap(bar_pos=np.zeros(3), stem_pos=np.ones(3)) == pytest.approx(np.sqrt(3))
    assert Scenario(scene=SceneSpec(pusher="capsule")).scene.pusher == "capsule"
    make_backend("cpu", Scenario(), nthread=1).close()


def test_demos_refuse_a_pixel_policy_saying_why(tmp_path, capsys):
    """Seventh pass: the committed pixel policy on gym-pusht's task was refused by `demos` as one that "looks at the
    chapter scene's camera": it is gym-pusht's, and acts on images, where the demos hand their controller the state."""
    pixels = _policy_path().parent.parent.parent / "dagger-pixels-gym-pusht-h200-16k/seed-0/policy.msgpack"
    assert main(["demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-progress",
                 "--controller", f"policy:{pixels}", "--out", str(tmp_path / "d")]) == 1
    one_line(capsys, "acts on images", "reads the state")
    assert not (tmp_path / "d").exists()


CONTROLLERS = """
import numpy as np
def raises(obs, t): raise RuntimeError("boom")
def nan3(obs, t): return np.full(obs["state"].shape[:-1] + (2,), np.nan if t >= 3 else 0.0)
def inf(obs, t): return np.full(obs["state"].shape[:-1] + (2,), np.inf)
def kbint(obs, t): raise KeyboardInterrupt
"""


@pytest.mark.parametrize("name, code", [("raises", 1), ("nan3", 1), ("kbint", 130)])
@pytest.mark.parametrize("backend", ["cpu", "gym-pusht"])
def test_a_batch_whose_controller_fails_before_any_chunk_leaves_nothing(tmp_path, monkeypatch, capsys, name, code,
                                                                         backend):
    """SILENT (seventh pass, 12 tries): a controller that raised, or returned NaN, at the first chunk was one line,
    but left .parts/manifest.json and .run.json: in a new --out a folder of bookkeeping, in a user's folder two
    files of ours. With no chunk finished there is nothing to resume: none is left. (Eighth pass: a controller
    raising KeyboardInterrupt, taken as ^C, exit 130, left them too.)"""
    (tmp_path / "ctl7.py").write_text(CONTROLLERS)
    monkeypatch.syspath_prepend(str(tmp_path))
    user = tmp_path / "user"
    user.mkdir()
    (user / "notes.md").write_text("mine")
    task = ["--task", "gym-pusht"] if backend == "gym-pusht" else []
    for out, extra in ((tmp_path / "new" / "o", []), (user, ["--share-out"])):
        assert main(over(RUNS["eval"], "--max-steps", "6", "--backend", backend, *task, "--controller", f"ctl7:{name}",
                     "--out", str(out), *extra)) == code
        one_line(capsys, f"ctl7:{name}" if code == 1 else "no chunk was finished yet")
    assert not (tmp_path / "new").exists()
    assert snapshot(user) == {"notes.md": b"mine"}


@pytest.mark.parametrize("argv, words", [
    (["train", "--backend", "cpu", "--fit-steps", "99999999999"], "--fit-steps: must be an integer from 1 to 2,147,483,647"),
    (["train", "--backend", "cpu", "--batch", "99999999999"], "--batch: must be an integer from 1 to 2,147,483,647"),
    (["sweep", "--chunk", "99999999999"], "--chunk: must be an integer from 1 to 16,777,216"),
    (["eval", "--chunk", "16777217"], "--chunk: must be an integer from 1 to 16,777,216"),
    (["demos", "--batch", "99999999999"], "--batch: must be an integer from 1 to 16,777,216"),
    (["demos", "--max-steps", "100001"], "--max-steps: must be an integer from 1 to 100,000"),
])
def test_counts_past_what_runs_are_refused_at_the_door(tmp_path, capsys, argv, words):
    """TRACEBACK and SILENT (seventh pass): `train --fit-steps` or `--batch` past 2**31-1 was JAX's OverflowError
    traceback after the banner; `--chunk` past a batch's bound was refused after .parts and .run.json were written;
    `demos --batch` huge was taken, `demos --max-steps` had no bound where eval's is 100,000."""
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    one_line(capsys, words)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("env_id", ["mjx_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"])
def test_success_threshold_set_on_the_env_is_checked_and_read(env_id):
    """SILENT (seventh pass): `env.unwrapped.success_threshold = 2.0` (or NaN) on PushT-v0 made an attribute nothing
    read; the drop-in's setter (gym-pusht's own attribute) is now both ids'. A value outside (0, 1] is one line; a
    threshold under the start's coverage ends the next step as a success."""
    import gymnasium as gym
    import numpy as np

    from mjx_pusht.errors import MjxPushtError

    env = gym.make(env_id)
    u = env.unwrapped
    for bad in (2.0, float("nan"), 0.0):
        with pytest.raises(MjxPushtError, match="success_threshold must be a number in"):
            u.success_threshold = bad
    seed = next(s for s in range(200) if 0.05 < env.reset(seed=s)[1]["coverage"] < 0.9)
    env.reset(seed=seed)
    still = np.zeros(2) if env_id.endswith("PushT-v0") else env.unwrapped._state.obs["state"][0, :2] * 0 + \
        env.reset(seed=seed)[1]["pos_agent"]  # stand still: zero velocity, or the pusher's own position
    assert not env.step(still)[2]  # at the task's 0.95: not a success
    env.reset(seed=seed)
    u.success_threshold = 0.01
    assert u.success_threshold == 0.01 and env.step(still)[2]


def test_first_fits_keep_the_minutes(tmp_path, capsys):
    """HANG (seventh pass): `train --minutes 0.5 --first-fits 99999999999` ran past the budget (and would have for
    days): every first fit ran whatever the clock said. Another first fit now starts only when the budget leaves
    time for it and the judgement after it, as every later fit."""
    import json
    import time

    t0 = time.monotonic()
    out = tmp_path / "o"
    assert main(["train", "--backend", "cpu", "--envs", "8", "--iterations", "1", "--fit-steps", "200", "--hidden",
                 "16", "--eval-envs", "4", "--max-steps", "10", "--no-progress", "--no-rerun", "--minutes", "0.1",
                 "--first-fits", "1000000", "--out", str(out)]) == 0, capsys.readouterr().err
    fits = json.loads((out / "first_fits.json").read_text())
    assert 1 <= len(fits["losses"]) < 1000000 and time.monotonic() - t0 < 60
    assert f"first fit from {len(fits['losses'])} initialisations (of 1000000" in capsys.readouterr().out


@pytest.mark.parametrize("argv, words", [
    (["train", "--backend", "cpu", "--action-eps", "1e308"], "--action-eps: must be a finite number > 0 and <= 1000"),
    (["train", "--backend", "cpu", "--lr", "1e308"], "--lr: must be a learning rate > 0 and at most 1e38"),
    (["compare", "--seeds", "2", "--reset", "easy"], "--reset set a controller's episodes"),
    (["compare", "--seeds", "2", "--max-steps", "5"], "--max-steps set a controller's episodes"),
    (["compare", "--seeds", "2", "--controller", "expert", "--tolerance", "1e-6"], "--tolerance set the open-loop"),
    (["compare", "--seeds", "2", "--controller", "expert", "--no-root-cause"], "--no-root-cause set the open-loop"),
])
def test_values_a_run_cannot_use_are_refused_at_the_door(tmp_path, capsys, argv, words):
    """TRACEBACK (seventh pass): `--action-eps 1e308` overflowed when squared; SILENT: `compare --reset easy` without
    --controller ran the open loop for 58 s and ignored --reset (as --max-steps)."""
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    one_line(capsys, words)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("pusher", ["cylinder", "capsule"])
def test_tree_json_reads_the_pusher_back(capsys, pusher):
    """SILENT (seventh pass): `tree --pusher capsule --json` was byte for byte `tree --json`: the tree's bodies and
    joints are the same for both pushers. The JSON now holds the pusher's geom type read from the compiled model."""
    import json

    assert main(["tree", "--pusher", pusher, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pusher"] == pusher


def test_output_into_a_closed_pipe_is_no_traceback(tmp_path):
    """Seen with the seventh pass: `mjx-pusht tree --json | head -2` was a BrokenPipeError traceback."""
    import subprocess
    import sys

    from helpers import ENV

    r = subprocess.run(f"{sys.executable} -m mjx_pusht tree --json | head -c 10", shell=True, capture_output=True,
                       text=True, env=ENV, executable="/bin/bash")
    assert r.stdout == '{\n  "bodie' and "Traceback" not in r.stderr and r.stderr == "", r.stderr


def test_functional_env_options_it_cannot_use_are_refused():
    """SILENT (seventh pass): PushTEnv(backend="cpu", raster=True) was accepted (MuJoCo's renderer draws there);
    reset_to(..., drawn="yes") took the string as True."""
    import numpy as np

    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.errors import MjxPushtError

    with pytest.raises(MjxPushtError, match="raster=True draws MJX's pixels"):
        PushTEnv(backend="cpu", raster=True)
    env = PushTEnv(backend="cpu")
    start = np.array([[0.1, 0.1, 0.0, -0.2, -0.2]] * 2)
    with pytest.raises(MjxPushtError, match="drawn must be True or False"):
        env.reset_to(start, drawn="yes")
    np.testing.assert_allclose(env.reset_to(start, drawn=False).obs["state"][:, 2:4], start[:, :2])


def test_an_interrupt_after_the_table_says_the_table_is_whole(tmp_path, monkeypatch, capsys):
    """SILENT (seventh pass): SIGINT once `sweep` had written its table said "no chunk was finished yet ... rerun
    without --resume": its chunks had been joined into the table, which was whole."""
    import mjx_pusht.study.sweep as sweep_module

    real = sweep_module.finish

    def finish_then_interrupt(out, run):
        real(out, run)
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_module, "finish", finish_then_interrupt)
    out = tmp_path / "o"
    assert main([*RUNS["sweep"], "--out", str(out)]) == 130
    one_line(capsys, f"the table {out}/per_seed.parquet is whole", "rerun the same command")
    capsys.readouterr()
    monkeypatch.undo()
    assert main([*RUNS["sweep"], "--out", str(out)]) == 0  # as it says: the same command writes the rest
    assert (out / "summary.json").is_file()


def test_a_video_named_into_its_own_new_out_is_written_and_a_folder_name_refused(tmp_path, capsys):
    """SURPRISE (seventh pass): `--out s/m1 --video s/m1/v.gif` was refused while s/m1 did not exist yet, though the
    run makes it; `--video s/dir.gif/` (a folder's name) wrote the file s/dir.gif."""
    out = tmp_path / "new"
    video = ["--video-size", "32", "--video-episodes", "2"]
    assert main([*RUNS["eval"], *video, "--video", str(out / "v.gif"), "--out", str(out)]) == 0, \
        capsys.readouterr().err
    assert (out / "v.gif").read_bytes()[:6] == b"GIF89a"
    assert main([*RUNS["eval"], *video, "--video", str(tmp_path / "nowhere" / "v.gif"), "--out", str(out)]) == 1
    one_line(capsys, "folder", "does not exist")
    assert main([*RUNS["eval"], *video, "--video", f"{tmp_path}/dir.gif/", "--out", str(tmp_path / "o")]) == 2
    one_line(capsys, "names a folder")
    assert not (tmp_path / "dir.gif").exists() and not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [["demos", "--backend", "cpu"], ["eval", "--backend", "gym-pusht", "--task",
                                                                   "gym-pusht", "--no-rerun"]])
def test_an_infinite_action_on_gym_pushts_scene_is_one_line_and_no_warning(tmp_path, argv):
    """SURPRISE (seventh pass): a controller's inf velocity was refused in one line after NumPy's two-line
    RuntimeWarning from turning it into gym-pusht's target (the demos; eval's gym-pusht workers too). Run as a
    user runs it (pytest would catch the warning in this process)."""
    import subprocess
    import sys

    from helpers import ENV

    (tmp_path / "ctl7.py").write_text(CONTROLLERS)
    env = {**ENV, "PYTHONPATH": os.pathsep.join(p for p in (str(tmp_path), ENV.get("PYTHONPATH", "")) if p)}
    r = subprocess.run([sys.executable, "-m", "mjx_pusht", *argv, "--seeds", "2", "--max-steps", "3", "--no-progress",
                        "--controller", "ctl7:inf", "--out", str(tmp_path / "o")], capture_output=True, text=True,
                       env=env)
    err = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 1 and len(err) == 1 and "non-finite action" in err[0], err


def test_a_signal_that_lands_in_a_gc_callback_still_ends_the_command(monkeypatch, capsys):
    """TRACEBACK (eighth pass): SIGTERM 7 s into a small `train` landed in JAX's gc callback: the KeyboardInterrupt
    raised there was printed ("Exception ignored in: <function _xla_gc_callback>") and dropped, and the command ran
    on to exit 0. A signal inside code that drops exceptions is sent again once that code has returned."""
    import gc
    import signal

    import mjx_pusht.model.tree as tree_module

    sent = []

    def callback(phase, info):  # as JAX's: a gc callback, where the signal's handler runs
        if phase == "start" and not sent:
            sent.append(os.kill(os.getpid(), signal.SIGTERM))
            for _ in range(1000):  # bytecodes for the handler to run in
                pass

    real = tree_module.read_tree

    def read_tree_collecting(model):
        import time

        gc.collect()
        time.sleep(0.5)  # the command's work goes on after the collection
        return real(model)

    monkeypatch.setattr(tree_module, "read_tree", read_tree_collecting)
    gc.callbacks.append(callback)
    try:
        assert main(["tree"]) == 128 + signal.SIGTERM
    finally:
        gc.callbacks.remove(callback)
    err = capsys.readouterr().err
    assert "Exception ignored" not in err and "terminated" in err and err.strip().count("\n") == 0, err
