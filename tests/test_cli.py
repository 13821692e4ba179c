"""The command line as a user meets it: outputs, determinism, and one-line errors for bad input."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mjx_pusht.cli.commands import main

ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mjx_pusht", *args], capture_output=True, text=True, env=ENV, cwd=cwd)


def test_two_smoke_runs_write_byte_identical_metrics(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        r = cli("scene", "--smoke", "--no-rerun", "--out", str(out))
        assert r.returncode == 0, r.stderr
    assert (a / "metrics.json").read_bytes() == (b / "metrics.json").read_bytes()


def test_scene_writes_the_chapter_keys_and_prints_the_verdict(tmp_path):
    r = cli("scene", "--no-rerun", "--out", str(tmp_path))
    assert r.returncode == 0, r.stderr
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert sorted(m) == [
        "break_it", "joint_types", "n_bodies", "n_geoms", "n_joints", "nq", "nu", "nv", "pusher_final", "seed",
        "tee_final_pose", "tee_gap_max_dev", "tee_gap_settled", "tee_settled_pose", "tee_stayed_rigid",
    ]
    assert list(m) == sorted(m)  # written sorted, like the chapter
    assert "tier:" in r.stdout and "wall-clock" in r.stdout and "RIGID" in r.stdout
    assert "from y=0.031 to y=0.376" in r.stdout
    assert "wall" not in json.dumps(m)  # timing goes to stdout, never metrics.json


def test_split_tee_prints_split_and_its_tree(tmp_path):
    r = cli("scene", "--break", "split-tee", "--no-rerun", "--out", str(tmp_path))
    assert r.returncode == 0
    assert "4 bodies under worldbody, 8 joints, nq=8 nv=8" in r.stdout and "SPLIT" in r.stdout
    assert json.loads((tmp_path / "metrics.json").read_text())["tee_stayed_rigid"] is False


def test_tree_json_is_the_expected_tree():
    r = cli("tree", "--json")
    assert r.returncode == 0
    t = json.loads(r.stdout)
    assert (t["n_bodies"], t["n_joints"], t["nq"], t["nv"], t["nu"]) == (3, 5, 5, 5, 2)


def _one_line_error(capsys, argv, code):
    assert main(argv) == code
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("mjx-pusht: error:") and "Traceback" not in err
    return err


@pytest.mark.parametrize(
    "argv",
    [
        ["scene", "--break", "wobbly"],
        ["scene", "--steps", "0"],
        ["scene", "--steps", "-5"],
        ["scene", "--steps", "ten"],
        ["scene", "--seed", "-1"],
        ["sweep", "--steps", "0"],
        ["sweep", "--break", "nope"],
        ["train", "--seed", "18446744073709551616"],  # was an OverflowError traceback
        ["train", "--seed", "2147483648"],  # JAX's key takes 32 bits: 2**31 would start as seed 0's networks do
    ],
)
def test_bad_flags_get_one_line_and_exit_2(capsys, argv):
    _one_line_error(capsys, argv, 2)


def test_out_that_is_a_file_is_refused_and_left_alone(capsys, tmp_path):
    f = tmp_path / "taken"
    f.write_text("keep me")
    err = _one_line_error(capsys, ["scene", "--out", str(f)], 1)
    assert "is a file" in err and f.read_text() == "keep me"


def test_out_that_cannot_be_written_is_refused(capsys, tmp_path):
    (tmp_path / "file").write_text("x")
    err = _one_line_error(capsys, ["scene", "--out", str(tmp_path / "file" / "sub")], 1)
    assert "not writable" in err


def test_bad_input_leaves_earlier_results_intact(capsys, tmp_path):
    assert main(["scene", "--no-rerun", "--out", str(tmp_path)]) == 0
    before = (tmp_path / "metrics.json").read_bytes()
    capsys.readouterr()
    _one_line_error(capsys, ["scene", "--steps", "0", "--out", str(tmp_path)], 2)
    assert (tmp_path / "metrics.json").read_bytes() == before
    assert sorted(p.name for p in Path(tmp_path).iterdir() if not p.name.startswith(".")) == ["metrics.json"]


def test_a_run_without_recording_does_not_leave_an_earlier_runs_recording_beside_its_results(tmp_path):
    assert main(["scene", "--seed", "1", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "scene.rrd").exists()
    assert main(["scene", "--seed", "2", "--no-rerun", "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in Path(tmp_path).iterdir() if not p.name.startswith(".")) == ["metrics.json"]


def test_results_are_written_with_the_usual_file_mode(tmp_path):
    import os

    assert main(["scene", "--no-rerun", "--out", str(tmp_path)]) == 0
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "metrics.json").stat().st_mode & 0o777 == 0o666 & ~mask
