"""A controller's NaN or infinite action stops the run, on every backend, before it drives the physics.

Before: `def act(obs, t): return np.full((n, 2), np.nan)` evaluated as "0 of 8 episodes" with exit 0, a broken
controller read as one that does not push. Now the first non-finite action of a live episode stops eval and
compare in one line naming the controller, the seed, the control step and the value; the chunks finished before
it stay, and --resume finishes the run. The controllers are in bad_actions.py.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from bad_actions import ByKey
from helpers import ENV, cli

from mjx_pusht.backends.actions import NonFiniteActionError
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.reset import start_poses

SCENARIO = Scenario(controller=ByKey(), reset="task", episode=Episode(max_steps=10))
TESTS = str(Path(__file__).parent)
NAN, INF = math.nan, math.inf

# (seeds of one batch, the (seed, control step, value) it stops at): bad_actions.CASES says which seed does what
STOPS = [
    ([0, 1, 104, 2], (104, 5, NAN)),  # one row, a later step
    ([0, 102, 1, 2], (102, 0, INF)),  # one row, the first step
    ([3, 2, 103, 0], (103, 0, -INF)),  # one row, the first step, -inf
    ([104, 101, 105, 106], (101, 0, NAN)),  # every row: the earliest step wins, not the first row
    ([105, 104, 106, 105], (105, 5, INF)),  # every row at one step: the first row in seed order
    ([106, 0, 0, 1], (106, 5, -INF)),
]


def same_value(a, b) -> bool:
    return all((math.isnan(x) and math.isnan(y)) or x == y for x, y in zip(a, b))


def assert_stops(e: NonFiniteActionError, seed: int, step: int, value: float) -> None:
    assert (e.seed, e.step) == (seed, step) and same_value(e.value, (value, value)), e.args
    line = str(e)
    assert "\n" not in line and "bad_actions:ByKey" in line and f"control step {step} of seed {seed}" in line
    assert repr(float(value)) in line


@pytest.mark.parametrize("seeds,stop", STOPS)
def test_on_mujoco_c_the_first_nonfinite_action_stops_the_rollout_before_mj_step_sees_it(seeds, stop, monkeypatch):
    from mjx_pusht.backends import cpu

    stepped = []
    real = cpu._Lockstep._step_rows

    def step_rows(self, u, rows):  # what reaches mj_step, seen from outside the check
        stepped.append(np.isfinite(u[rows]).all())
        return real(self, u, rows)

    monkeypatch.setattr(cpu._Lockstep, "_step_rows", step_rows)
    with pytest.raises(NonFiniteActionError) as e:
        cpu.run_cpu(SCENARIO, np.array(seeds))
    assert_stops(e.value, *stop)
    assert all(stepped) and len(stepped) == stop[1]  # every step before the bad one ran; that one did not


def test_finite_actions_run_as_before_and_an_ended_episodes_action_is_not_checked():
    from mjx_pusht.backends.cpu import run_cpu
    from mjx_pusht.task.controllers import Zero

    ok = run_cpu(SCENARIO, np.arange(4))
    zero = run_cpu(Scenario(controller=Zero(), reset="task", episode=Episode(max_steps=10)), np.arange(4))
    np.testing.assert_array_equal(ok.final, zero.final)  # ByKey is the zero controller on these seeds
    assert (ok.episode["length"] == 10).all()


def test_worker_processes_stop_at_the_step_one_process_stops_at():
    # eval on the CPU spreads feedback episodes over processes: the error is the one a single process raises
    from mjx_pusht.backends.cpu import CpuBackend, run_cpu

    seeds = np.array([0, 1, 2, 3, 104, 5, 6, 103])
    with pytest.raises(NonFiniteActionError) as one:
        run_cpu(SCENARIO, seeds)
    backend = CpuBackend(SCENARIO, workers=2)
    try:
        with pytest.raises(NonFiniteActionError) as pooled:
            backend.run(seeds)
    finally:
        backend.close()
    assert pooled.value.args == one.value.args and (one.value.seed, one.value.step) == (103, 0)


def _user_env(**bad) -> dict:
    return {**ENV, "PYTHONPATH": os.pathsep.join([TESTS, ENV.get("PYTHONPATH", "")]),
            **{f"BAD_{k.upper()}": str(v) for k, v in bad.items()}}


def _one_error_line(r) -> str:
    assert r.returncode == 1, (r.returncode, r.stdout[-500:], r.stderr[-1000:])
    assert "Traceback" not in r.stderr
    errors = [line for line in r.stderr.splitlines() if "error" in line.lower()]  # beside the progress bar
    assert len(errors) == 1, r.stderr
    return errors[0]


@pytest.mark.parametrize("value", ["inf", pytest.param("nan", marks=pytest.mark.slow),
                                   pytest.param("-inf", marks=pytest.mark.slow)])
def test_eval_of_a_controller_returning_nonfinite_actions_is_one_line_and_a_nonzero_exit(tmp_path, value):
    r = cli("eval", "--backend", "cpu", "--controller", "bad_actions:act", "--seeds", "4", "--max-steps", "5",
            "--no-rerun", "--no-progress", "--out", str(tmp_path / "o"), env=_user_env(value=value))
    line = _one_error_line(r)
    assert "controller bad_actions:act" in line and "control step 0 of seed 0" in line
    assert f"[{float(value)!r}, {float(value)!r}]" in line
    assert not (tmp_path / "o" / "per_episode.parquet").exists() and not (tmp_path / "o" / "summary.json").exists()


def _later_bad_row(backend: str, tmp_path, chunk: str, extra=()) -> None:
    """Seed 5 of 0..7 goes bad at step 3, in the third chunk of two: two chunks stay, --resume finishes."""
    out = tmp_path / "o"
    args = ("eval", "--backend", backend, "--controller", "bad_actions:act", "--seeds", "8", "--max-steps", "6",
            "--chunk", chunk, "--no-rerun", "--no-progress", "--out", str(out), *extra)
    x = start_poses([5], reset="task")[0, 0]
    r = cli(*args, env=_user_env(value="nan", step=3, tee_x=repr(float(x))))
    line = _one_error_line(r)
    assert "control step 3 of seed 5" in line and "[nan, nan]" in line and "--resume" in line
    kept = sorted(p.name for p in (out / ".parts").glob("seeds-*.parquet"))
    assert kept == [f"seeds-{lo:012d}-{lo + int(chunk):012d}.parquet" for lo in range(0, 4, int(chunk))]
    assert not (out / "per_episode.parquet").exists()
    r = cli(*args, "--resume", env=_user_env(value="0.01"))  # "fixed": every row now pushes at 0.01 m/s
    assert r.returncode == 0, r.stderr[-1000:]
    from mjx_pusht.io.outputs import read_table

    t = read_table(out / "per_episode.parquet")
    assert list(t["seed"]) == list(range(8)) and np.isfinite(t["tee_final_x"]).all()
    moved = np.hypot(t["pusher_final_x"] - t["pusher_start_x"], t["pusher_final_y"] - t["pusher_start_y"]) > 1e-3
    assert list(moved) == [False] * 4 + [True] * 4  # the first two chunks are the kept ones: their pusher held still


def test_the_chunks_finished_before_a_bad_action_stay_and_resume_finishes_the_eval(tmp_path):
    _later_bad_row("cpu", tmp_path, "2")


# MJX-Warp on Warp's CPU device: the check is a per-row record carried in the compiled scan


@pytest.fixture(scope="module")
def warp_backend():
    from mjx_pusht.backends.mjx import MjxBackend
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    backend = MjxBackend(SCENARIO, "warp")
    backend.run(np.arange(4), batch=4)  # compiled once; every case below runs this program
    return backend


@pytest.mark.slow
@pytest.mark.warp
@pytest.mark.parametrize("seeds,stop", STOPS)
def test_on_mjx_warp_the_scan_carries_the_first_nonfinite_action_and_the_chunk_is_refused(warp_backend, seeds, stop):
    with pytest.raises(NonFiniteActionError) as e:
        warp_backend.run(np.array(seeds), batch=4)
    assert_stops(e.value, *stop)


@pytest.mark.slow
@pytest.mark.warp
def test_on_mjx_warp_finite_rows_and_padding_are_not_flagged(warp_backend):
    r = warp_backend.run(np.array([0, 1, 2]), batch=4)  # the padding row repeats seed 2
    assert r.finite.all() and (r.episode["length"] == 10).all()
    with pytest.raises(NonFiniteActionError) as e:  # a bad seed as the row the padding copies
        warp_backend.run(np.array([0, 104]), batch=4)
    assert (e.value.seed, e.value.step) == (104, 5)


@pytest.mark.slow
@pytest.mark.warp
def test_mjx_warp_eval_stops_at_a_later_bad_row_keeps_its_chunks_and_resumes(tmp_path):
    _later_bad_row("mjx-warp", tmp_path, "2")


@pytest.mark.slow
@pytest.mark.warp
def test_compare_of_a_controller_returning_nan_is_one_line(tmp_path):
    r = cli("compare", "--controller", "bad_actions:act", "--backend", "mjx-warp", "--seeds", "2", "--max-steps",
            "4", "--out", str(tmp_path / "c"), env=_user_env(value="-inf", step=2))
    line = _one_error_line(r)
    assert "controller bad_actions:act" in line and "control step 2 of seed 0" in line and "[-inf, -inf]" in line
    assert not (tmp_path / "c" / "compare_episodes.json").exists()


@pytest.mark.slow
@pytest.mark.warp
def test_on_mjx_warp_a_controller_that_looks_is_checked_in_its_own_scan_too():
    # a pixel controller's rollout is a scan of the vmapped step (MJX-Warp renders the batch at once), not the
    # vmapped scan: the record rides in that carry as well
    from bad_actions import Looks

    from mjx_pusht.backends.mjx import MjxBackend

    backend = MjxBackend(Scenario(controller=Looks(), reset="task", episode=Episode(max_steps=4)), "warp")
    with pytest.raises(NonFiniteActionError) as e:
        backend.run(np.arange(2), batch=2)
    assert (e.value.seed, e.value.step) == (0, 2) and all(math.isnan(v) for v in e.value.value)
