"""Issue 23's findings, each made small: bad input is one line and a non-zero exit, nothing written is lost."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import cli

from mjx_pusht.study.seeds import SeedSpecError, parse_seeds

gym = pytest.importorskip("gymnasium")
import mjx_pusht  # noqa: E402,F401

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
    with pytest.raises(ValueError, match="unknown reset option"):
        envs.reset(options={"reset_mask_typo": True})
    with pytest.raises(ValueError, match="a seed is an integer"):
        envs.reset(seed=2**64)
    with pytest.raises(ValueError, match="num_envs must be a positive integer"):
        gym.make_vec(ENV, num_envs=2.7, backend="cpu")
    with pytest.raises(ValueError, match="image size"):
        gym.make_vec(ENV, num_envs=2, backend="cpu", obs_type="pixels", observation_size=0)
    env = gym.make(ENV)
    with pytest.raises(ValueError, match="a seed is an integer"):
        env.reset(seed=2**64)
    with pytest.raises(ValueError, match="unknown reset option"):
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
    import os
    import subprocess
    import sys

    from helpers import ENV as RUN_ENV

    env = {**RUN_ENV, "MUJOCO_GL": "osmesa"}
    r = cli("tree", env=env)
    assert r.returncode == 0 and "kinematic tree" in r.stdout, r.stderr[-500:]
    code = ("import gymnasium as gym, mjx_pusht\n"
            "from mjx_pusht.envs.pixels import PixelsError\n"
            "try:\n    gym.make('mjx_pusht/PushT-v0', obs_type='pixels')\n"
            "except PixelsError as e:\n    print('REFUSED', e)\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=os.getcwd())
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
