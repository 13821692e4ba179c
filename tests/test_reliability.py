"""A hostile pass's findings, each made small: bad input is one line and a non-zero exit, nothing written is lost."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import cli

from mjx_pusht.study.seeds import SeedSpecError, parse_seeds

gym = pytest.importorskip("gymnasium")
import mjx_pusht  # noqa: F401

ENV = "mjx_pusht/PushT-v0"


@pytest.mark.parametrize("spec", ["9223372036854775807", "10000000000", "0:9223372036854775807"])
def test_a_seed_count_beyond_one_run_is_refused_not_an_empty_table(spec):
    with pytest.raises(SeedSpecError, match="at most 2"):
        parse_seeds(spec)


def test_a_huge_seed_count_leaves_a_finished_folder_as_it_was(tmp_path):
    out = tmp_path / "done"
    out.mkdir()
    (out / "per_seed.parquet").write_bytes(b"finished results")
    r = cli("sweep", "--backend", "cpu", "--seeds", "9223372036854775807", "--out", str(out))
    assert r.returncode != 0
    assert len(r.stderr.strip().splitlines()) == 1 and "at most 2**30" in r.stderr
    assert (out / "per_seed.parquet").read_bytes() == b"finished results"


@pytest.mark.parametrize("bad", [np.zeros(3), 0.5, None])
def test_single_env_actions_of_the_wrong_shape_are_one_line(bad):
    env = gym.make(ENV)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.step(bad)


def test_vector_env_inputs_are_checked_up_front():
    envs = gym.make_vec(ENV, num_envs=3, backend="cpu")
    with pytest.raises(ValueError, match="first reset starts every environment"):
        envs.reset(options={"reset_mask": np.array([True, False, False])})
    with pytest.raises(ValueError, match="reset_to_state"):
        envs.reset(options={"reset_to_state": np.zeros((5, 5))})
    with pytest.raises(ValueError, match="finite"):
        envs.reset(options={"reset_to_state": [np.nan, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match="takes no option 'reset_mask_typo'"):  # a typo was ignored: refused
        envs.reset(options={"reset_mask_typo": True})
    envs.reset(options={"lerobot_new_rollout": True})  # LeRobot's own option: still ignored
    with pytest.raises(ValueError, match="seed must be an integer"):
        envs.reset(seed=2**64)
    with pytest.raises(ValueError, match="num_envs must be an integer from 1"):
        gym.make_vec(ENV, num_envs=2.7, backend="cpu")
    with pytest.raises(ValueError, match="observation_size must be an integer from 8"):
        gym.make_vec(ENV, num_envs=2, backend="cpu", obs_type="pixels", observation_size=0)
    env = gym.make(ENV)
    with pytest.raises(ValueError, match="seed must be an integer"):
        env.reset(seed=2**64)
    with pytest.raises(ValueError, match="takes no option 'reset_to'"):  # a misspelt reset_to_state: was ignored
        env.reset(options={"reset_to": [0, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match="finite"):
        env.reset(options={"reset_to_state": [0, 0, np.inf, 0, 0]})


def _without_osmesa():
    import ctypes.util

    if ctypes.util.find_library("OSMesa"):
        pytest.skip("OSMesa is installed here: MUJOCO_GL=osmesa is not a missing GL on this machine")


def test_a_mujoco_gl_whose_library_is_missing_breaks_only_pixels(tmp_path):
    # finding 6: MUJOCO_GL=osmesa without OSMesa broke `import mujoco`, so every command died at import
    _without_osmesa()
    from helpers import ENV as RUN_ENV
    from helpers import pixels_refusal

    env = {**RUN_ENV, "MUJOCO_GL": "osmesa"}
    r = cli("tree", env=env)
    assert r.returncode == 0 and "kinematic tree" in r.stdout, r.stderr[-500:]
    p = pixels_refusal(env)
    assert "REFUSED MUJOCO_GL=osmesa but OSMesa" in p.stdout, p.stderr[-500:]


def test_a_controller_that_calls_exit_is_one_line_not_a_silent_exit_code(tmp_path):
    # finding 7: a controller raising SystemExit(3) ended the run with exit 3 and no message
    import os

    from helpers import ENV as RUN_ENV

    (tmp_path / "quits.py").write_text("def policy(obs, t):\n    raise SystemExit(3)\n")
    env = {**RUN_ENV, "PYTHONPATH": f"{tmp_path}{os.pathsep}{RUN_ENV.get('PYTHONPATH', '')}"}
    r = cli("eval", "--backend", "cpu", "--controller", "quits:policy", "--seeds", "2", "--no-rerun",
            "--out", str(tmp_path / "out"), env=env)
    assert r.returncode == 1, (r.returncode, r.stderr[-500:])
    errors = [line for line in r.stderr.splitlines() if "error" in line.lower()]  # beside the progress bar
    assert len(errors) == 1 and "called exit(3)" in errors[0] and "Traceback" not in r.stderr


def test_a_failed_chunk_write_stops_the_sweep_at_once_and_resume_finishes_it(tmp_path, monkeypatch):
    """Finding 5: on a full disk the chunks stopped landing at seed 14,000 of 40,000 but the sweep ran
    to 100% before failing. Now the first failed write stops it (one line), and --resume completes it."""
    import errno

    from mjx_pusht.backends.cpu import CpuBackend
    from mjx_pusht.io.outputs import OutputError, read_table
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.study import sweep

    real = sweep.atomic_write_table
    calls = []

    def disk_full_after_one(path, cols):
        calls.append(path.name)
        if len(calls) > 1:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(path, cols)

    seeds, config = np.arange(40), {"backend": "cpu", "break_it": "none", "steps": 120}
    backend = CpuBackend(Scenario())
    monkeypatch.setattr(sweep, "atomic_write_table", disk_full_after_one)
    with pytest.raises(OutputError, match="No space left on device.*1 chunk files kept.*--resume"):
        sweep.run_sweep(backend, seeds, tmp_path / "cut", config=config, chunk=4, progress=False)
    assert len(calls) <= 3  # the failed chunk, and at most one launched before it was seen: not all 10
    monkeypatch.setattr(sweep, "atomic_write_table", real)
    resumed = sweep.run_sweep(backend, seeds, tmp_path / "cut", config=config, chunk=4, resume=True, progress=False)
    sweep.finish(tmp_path / "cut", resumed)
    whole = sweep.run_sweep(backend, seeds, tmp_path / "whole", config=config, chunk=4, progress=False)
    sweep.finish(tmp_path / "whole", whole)
    a, b = read_table(tmp_path / "whole" / "per_seed.parquet"), read_table(tmp_path / "cut" / "per_seed.parquet")
    assert list(a) == list(b) and all(np.array_equal(a[k], b[k]) for k in a)


def test_a_recording_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    """Finding 5: a 0-byte sweep.rrd was left. A recording that fails midway leaves no .rrd (and an
    earlier complete one stays as it was); a finished one is renamed into place."""
    from mjx_pusht.io import record

    out = tmp_path / "s"
    r = cli("sweep", "--backend", "cpu", "--seeds", "4", "--record", "2", "--out", str(out))
    assert r.returncode == 0, r.stderr
    good = (out / "sweep.rrd").read_bytes()
    assert len(good) > 1000 and not list(out.glob(".*partial"))

    def broken(*a, **k):
        raise RuntimeError("killed mid-recording")

    monkeypatch.setattr(record, "_log_static_scene", broken)
    from mjx_pusht.backends.cpu import CpuBackend
    from mjx_pusht.scenario import Scenario

    backend = CpuBackend(Scenario())
    rows = backend.run(np.arange(2), trace=True)
    with pytest.raises(RuntimeError, match="killed mid-recording"):
        record.record_sweep(out / "sweep.rrd", backend.model, rows, rows, ["seed 0", "seed 1"])
    assert (out / "sweep.rrd").read_bytes() == good


def test_a_model_mujoco_calls_singular_is_refused_or_flagged_never_finite_and_rigid(tmp_path):
    """Finding 7: --param tee_mass=1e-300 made MuJoCo warn "Inertia matrix ... singular"; nothing moved and
    every row read finite and rigid. Such a mass is now refused at the parameter's bounds (model.params.BOUNDS),
    in one line; a model MuJoCo still calls singular carries the warning on each of its rows, and such a row is
    never counted rigid."""
    import mujoco

    from mjx_pusht.backends.results import Rollouts
    from mjx_pusht.model.params import apply, model_warnings
    from mjx_pusht.model.scene import SceneSpec, build_model

    singular = apply(build_model(SceneSpec()), {"tee_mass": 1e-300})
    d = mujoco.MjData(singular)
    mujoco.mj_forward(singular, d)
    assert d.warning[mujoco.mjtWarning.mjWARN_INERTIA].number > 0  # MuJoCo's own verdict on this model
    inertia = 1 << int(mujoco.mjtWarning.mjWARN_INERTIA)
    assert model_warnings(singular) & inertia and model_warnings(build_model(SceneSpec())) == 0
    rows = Rollouts(seeds=np.arange(2), start=np.zeros((2, 3)), settled=np.zeros((2, 3)), final=np.zeros((2, 3)),
                    pusher_final=np.zeros((2, 2)), gap_settled=np.full(2, 0.06), gap_max_dev=np.zeros(2),
                    finite=np.ones(2, bool), contained=np.ones(2, bool), warnings=np.array([inertia, 0], np.int32))
    assert rows.rigid.tolist() == [False, True]

    r = cli("sweep", "--backend", "cpu", "--seeds", "3", "--param", "tee_mass=1e-300,0.105", "--no-rerun",
            "--out", str(tmp_path / "s"))
    assert r.returncode != 0 and "tee_mass must be a finite number in [0.01, 1e+08]" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "s").exists()


def test_mjx_rows_carry_the_model_check_too():
    # MJX raises no warnings of its own: its rows take MuJoCo's verdict on each parameter combination's model
    import jax

    from mjx_pusht.backends.grid import ModelGrid
    from mjx_pusht.model.scene import SceneSpec, build_model

    grid = ModelGrid(build_model(SceneSpec(pusher="capsule")), [{"tee_mass": 1e-300}, {"tee_mass": 0.105}], impl="jax",
                     device=jax.devices()[0])
    assert grid.warnings[0] != 0 and grid.warnings[1] == 0


def _files(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")}


def test_a_folder_with_another_commands_results_is_refused_whatever_the_flags(tmp_path):
    """Finding 3: a sweep into a finished eval folder replaced its summary.json and left per_episode.parquet
    without one. Then --replace deleted the eval's table. Now it is one line naming what is there, with
    or without --replace, and the folder is as it was."""
    out = tmp_path / "ev"
    assert cli("eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-rerun", "--out", str(out)).returncode == 0
    before = _files(out)
    for extra in ([], ["--replace"]):
        r = cli("sweep", "--backend", "cpu", "--seeds", "2", "--no-rerun", "--out", str(out), *extra)
        assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "holds eval's results (per_episode.parquet, summary.json)" in r.stderr and "whatever the flags" in r.stderr
        assert _files(out) == before


def test_a_summary_json_no_run_wrote_is_not_overwritten(tmp_path):
    """A folder holding someone's own summary.json (no mjx-pusht run's file beside it) was taken as empty, and the
    run replaced the file. Now it is one line and the file stays, --replace or not."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "summary.json").write_text("precious")
    for extra in ([], ["--replace"]):
        r = cli("sweep", "--backend", "cpu", "--seeds", "2", "--no-rerun", "--out", str(out), *extra)
        assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1
        assert "holds files no mjx-pusht run wrote here (summary.json)" in r.stderr
        assert (out / "summary.json").read_text() == "precious"


def test_a_finished_sweep_is_not_overwritten_by_other_seeds_but_may_be_rerun(tmp_path):
    """Finding 3: --resume on a finished sweep with other seeds overwrote it."""
    out = tmp_path / "sw"
    assert cli("sweep", "--backend", "cpu", "--seeds", "4", "--no-rerun", "--out", str(out)).returncode == 0
    before = _files(out)
    for extra in ([], ["--resume"]):
        r = cli("sweep", "--backend", "cpu", "--seeds", "5", "--no-rerun", "--out", str(out), *extra)
        assert r.returncode == 1 and "other seeds' or settings' finished results" in r.stderr
        assert _files(out) == before
    r = cli("sweep", "--backend", "cpu", "--seeds", "4", "--no-rerun", "--out", str(out))  # the same run again
    assert r.returncode == 0, r.stderr
    assert _files(out)["per_seed.parquet"] == before["per_seed.parquet"]


def test_a_second_run_into_a_folder_in_use_is_one_line(tmp_path):
    """Finding 6: two sweeps started together into one --out: the loser died with FileNotFoundError in
    .parts. Now the folder is locked while a run holds it; the second stops before any work."""
    from mjx_pusht.io.outputs import claim_out_dir, held_folders

    out = tmp_path / "busy"
    with held_folders():
        claim_out_dir(out, "sweep", {"seeds": "elsewhere"})  # this test process is the first run
        r = cli("sweep", "--backend", "cpu", "--seeds", "4", "--no-rerun", "--out", str(out))
        assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1
        assert "in use by another mjx-pusht run" in r.stderr and not (out / ".parts").exists()
    r = cli("sweep", "--backend", "cpu", "--seeds", "4", "--no-rerun", "--out", str(out))  # let go: it runs
    assert r.returncode == 0, r.stderr


def _descendants(pid: int) -> set[int]:
    """Every live process under `pid`, from /proc (workers, and the resource tracker)."""
    from pathlib import Path

    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not __import__("os").path.exists("/proc"), reason="reads the process tree from /proc")
def test_no_worker_outlives_a_killed_eval(tmp_path):
    """Finding 4: after kill -9 of a CPU eval, its spawn workers and resource tracker lived on under PID 1."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from helpers import ENV as RUN_ENV

    p = subprocess.Popen([sys.executable, "-m", "mjx_pusht", "eval", "--backend", "cpu", "--seeds", "2000",
                          "--chunk", "200", "--no-rerun", "--no-progress", "--out", str(tmp_path / "ev")],
                         env=RUN_ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        kids: set[int] = set()
        while time.time() < deadline and len(kids) < 3:  # two workers and the resource tracker
            time.sleep(0.5)
            kids = _descendants(p.pid)
        assert len(kids) >= 3, "the eval never started its workers"
        time.sleep(2)  # let them get to work
        kids = _descendants(p.pid)
    finally:
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(_alive(k) for k in kids):
        time.sleep(0.2)
    assert not [k for k in kids if _alive(k)], "processes outlived their killed parent"


def test_workers_from_a_script_without_a_main_guard_are_one_line(tmp_path):
    """Finding 4: workers=2 from a script without a __main__ guard: BrokenProcessPool, the script re-run by
    the children (banner printed 3 times). Now it stops in one line, before any process is spawned."""
    import subprocess
    import sys

    from helpers import ENV as RUN_ENV

    script = tmp_path / "unguarded.py"
    script.write_text(
        "import numpy as np\n"
        "from mjx_pusht.backends.factory import make_backend\n"
        "from mjx_pusht.scenario import Scenario\n"
        "from mjx_pusht.task.controllers import load\n"
        "print('BANNER')\n"
        "backend = make_backend('cpu', Scenario(reset='task', controller=load('expert')), workers=2)\n"
        "print(backend.run(np.arange(8)).finite.all())\n")
    r = subprocess.run([sys.executable, str(script)], env=RUN_ENV, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode != 0 and r.stdout.count("BANNER") == 1
    assert "ConfigError" in r.stderr and 'if __name__ == "__main__":' in r.stderr.strip().splitlines()[-1]
    assert "BrokenProcessPool" not in r.stderr
    guarded = tmp_path / "guarded.py"
    lines = script.read_text().splitlines()
    guarded.write_text("\n".join(lines[:4]) + "\nif __name__ == '__main__':\n" + "\n".join("    " + s for s in lines[4:]) + "\n")
    r = subprocess.run([sys.executable, str(guarded)], env=RUN_ENV, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 0 and r.stdout.split() == ["BANNER", "True"], r.stderr[-800:]


def test_a_video_that_cannot_be_written_is_one_line_before_the_episodes(tmp_path):
    """Finding 6: --video into a read-only folder was an OSError after the episodes ran; --video naming a
    folder dir.gif was IsADirectoryError and a half-written dir.gif.partial.gif beside it."""
    import os

    (tmp_path / "dir.gif").mkdir()
    cases = [(tmp_path / "dir.gif", "is a folder")]
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        cases.append((ro / "v.gif", "cannot write the video into"))
    elif os.path.isdir("/sys"):  # root writes through a read-only mode, but not into sysfs
        cases.append((__import__("pathlib").Path("/sys/v.gif"), "cannot write the video into /sys"))
    for video, needle in cases:
        out = tmp_path / f"out-{video.parent.name}"
        r = cli("eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-rerun", "--video", str(video),
                "--out", str(out))
        assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and needle in r.stderr, r.stderr
        assert not (out / "per_episode.parquet").exists()  # refused before any episode ran
    assert [p.name for p in tmp_path.iterdir() if "partial" in p.name] == []


def _interrupted_sweep(folder):
    """A sweep of seeds 0..3 in chunks of 2 stopped after its first chunk, as an interrupted run leaves it."""
    from mjx_pusht.io.outputs import atomic_write_json, atomic_write_table, read_table
    from mjx_pusht.study.sweep import fingerprint

    args = ("sweep", "--backend", "cpu", "--seeds", "4", "--steps", "5", "--chunk", "2", "--no-rerun", "--no-progress",
            "--out", str(folder))
    assert cli(*args).returncode == 0
    table = read_table(folder / "per_seed.parquet")
    (folder / "per_seed.parquet").unlink()
    (folder / "summary.json").unlink()
    (folder / ".parts").mkdir()
    atomic_write_json(folder / ".parts" / "manifest.json", fingerprint(
        np.arange(4), {"backend": "cpu", "break_it": "none", "steps": 5, "params": []}))
    atomic_write_table(folder / ".parts" / "seeds-000000000000-000000000002.parquet", {k: v[:2] for k, v in table.items()})
    return args, table


def test_resume_of_a_damaged_unfinished_sweep_is_one_line_before_any_work(tmp_path):
    """The hostile pass: a cut chunk file or an unreadable manifest in .parts raised pyarrow's or json's traceback
    (the chunk only at the end, after every other seed had run). Now --resume refuses in one line naming the file,
    and an undamaged one finishes the table."""
    from mjx_pusht.io.outputs import read_table

    args, table = _interrupted_sweep(tmp_path / "ok")
    assert cli(*args, "--resume").returncode == 0
    assert all(np.array_equal(read_table(tmp_path / "ok" / "per_seed.parquet")[k], table[k]) for k in table)
    for damage in ("manifest.json", "seeds-000000000000-000000000002.parquet"):
        folder = tmp_path / damage.split(".")[0]
        _interrupted_sweep(folder)
        (folder / ".parts" / damage).write_bytes(b"{cut")
        r = cli(*args[:-1], str(folder), "--resume")
        assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and damage in r.stderr, r.stderr
        assert "Traceback" not in r.stderr and not (folder / ".parts" / "seeds-000000000002-000000000004.parquet").exists()
