"""The PushT task, closed loop: the environment API, the controllers, the expert, and evaluation."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.backends.results import COLUMNS
from mjx_pusht.cli.commands import main
from mjx_pusht.io.outputs import read_table
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.stats import wilson
from mjx_pusht.task.controllers import (
    Expert,
    FromFunction,
    Nudge,
)
from mjx_pusht.task.episode import Episode


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


@pytest.mark.slow
def test_mjx_jax_runs_the_expert_in_the_scan_and_solves_the_chapter_starts():
    from mjx_pusht.backends.mjx import MjxBackend

    sc = Scenario(reset="chapter", controller=Expert(), episode=Episode(max_steps=120))
    backend = MjxBackend(sc, "jax")
    r = backend.run(np.arange(4))
    assert r.episode["success"].all() and r.rigid.all()
    compiled = backend.compile_seconds
    again = backend.run(np.arange(4, 7), batch=4)  # another chunk of the same batch shape: no second compile
    assert backend.compile_seconds == compiled and len(backend.runner._fns) == 1
    assert again.episode["success"].all()


@pytest.mark.slow
@pytest.mark.warp
def test_mjx_warp_runs_the_expert_in_the_scan_and_eval_through_the_cli_matches_the_cpu(tmp_path):
    """The expert inside MJX-Warp's scan, run by `eval` (which builds MjxBackend(scenario, "warp") and rolls it out):
    it solves both chapter starts as MuJoCo C does, each within 3 control steps of the CPU's step of success. One
    eval of the same 2 seeds and 80 steps serves both checks: the steps dominate here (Warp's kernels on the CPU),
    and a direct MjxBackend run of the same scenario beside it was the same rollout again."""
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    common = ["--seeds", "2", "--reset", "chapter", "--max-steps", "80", "--no-rerun", "--no-progress"]
    assert main(["eval", *common, "--backend", "mjx-warp", "--out", str(tmp_path / "w")]) == 0
    assert main(["eval", *common, "--backend", "cpu", "--out", str(tmp_path / "c")]) == 0
    w, c = read_table(tmp_path / "w" / "per_episode.parquet"), read_table(tmp_path / "c" / "per_episode.parquet")
    assert w["seed"].tolist() == c["seed"].tolist() == [0, 1]
    assert w["success"].tolist() == c["success"].tolist() == [True, True]
    assert np.abs(np.asarray(w["steps_to_success"]) - np.asarray(c["steps_to_success"])).max() <= 3
    summary = json.loads((tmp_path / "w" / "summary.json").read_text())
    assert summary["backend"] == "mjx-warp" and "primitive box_box" in summary["collision_functions"]["box-box"]
