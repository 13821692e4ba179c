"""The twelfth hostile pass's findings that are fixed, each run again as written (docs/notebook/hostile12.md; the
rest are in docs/notebook/boundary.md, "After the twelfth pass")."""

from __future__ import annotations

import json

import pytest
from fuzzing import snapshot
from helpers import RUNS, cli, one_line

from mjx_pusht import Scenario
from mjx_pusht.cli import main
from mjx_pusht.errors import ConfigError, MjxPushtError


@pytest.mark.parametrize("state", ["x", None, 5])
def test_brax_check_takes_a_state(state):
    """TRACEBACK (twelfth pass): BraxPushT().check('x') was an AttributeError ('str' object has no attribute 'info')."""
    pytest.importorskip("brax")
    from mjx_pusht.envs.brax import BraxPushT

    with pytest.raises(MjxPushtError, match="check takes the State"):
        BraxPushT(backend="mjx-jax", max_worlds=4, table=2).check(state)


@pytest.mark.parametrize("below", [("new",), ("new", "deeper")])
def test_a_new_out_anywhere_inside_another_runs_folder_is_refused(tmp_path, capsys, below):
    """SILENT (twelfth pass, 4 tries): `--out EVAL/newdir` (EVAL a finished eval's folder) was accepted: the claim
    looked only at the folder's parent. Every folder above is looked at now, and the refused run leaves nothing."""
    finished = tmp_path / "eval"
    assert main([*RUNS["eval"], "--out", str(finished)]) == 0, capsys.readouterr().err
    capsys.readouterr()
    before = snapshot(finished)
    for command in ("eval", "sweep", "demos"):
        for extra in ([], ["--replace"]):
            assert main([*RUNS[command], "--out", str(finished.joinpath(*below)), *extra]) == 1
            one_line(capsys, "is inside the eval run in", "never writes into another run's folder")
            assert snapshot(finished) == before
    # and a video named under it, however deep
    (finished / "pics").mkdir()
    before = snapshot(finished)
    assert main([*RUNS["eval"], "--video", str(finished / "pics" / "v.gif"), "--out", str(tmp_path / "b")]) == 1
    one_line(capsys, "inside another run's folder")
    assert snapshot(finished) == before and not (tmp_path / "b").exists()


def test_mjx_warp_refuses_float64_in_one_line():
    """MuJoCo Warp computes in float32 only: asked for float64 it was Warp's FFI TypeError ('expected float32,
    got float64') at the first step, after the compile."""
    pytest.importorskip("warp")
    from mjx_pusht.backends.mjx import MjxBackend

    with pytest.raises(ConfigError, match="MuJoCo Warp computes in float32 only"):
        MjxBackend(Scenario(), "warp", x64=True)


@pytest.mark.slow
def test_compare_on_mjx_warp_with_its_root_cause_runs_and_says_float64_was_not_run(tmp_path):
    """TRACEBACK (twelfth pass): `compare --backend mjx-warp` (the root-cause runs on, as getting-started.md gives
    it) ended in Warp's TypeError at its float64 run. The report now has the other root-cause runs, and says why
    float64 is not among them. Run as a user runs it: its own process (x64 is process-wide in JAX)."""
    pytest.importorskip("warp")
    r = cli("compare", "--backend", "mjx-warp", "--seeds", "2", "--out", str(tmp_path / "c"))
    assert r.returncode == 0, r.stderr[-2000:]
    rc = json.loads((tmp_path / "c" / "compare.json").read_text())["root_cause"]
    assert rc["mjx_x64"].startswith("not run: MuJoCo Warp computes in float32 only")
    assert rc["mjx_iter200_ls100_tol1e-10"]["final_pose_diff"]["median_m"] < 1e-2  # it ran, and near the CPU
    assert "| mjx_x64 | not run" in (tmp_path / "c" / "compare.md").read_text()
