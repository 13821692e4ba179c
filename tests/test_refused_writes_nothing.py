"""A refused run writes nothing, and a finished one leaves no lock file.

Before: every claimed --out got a `.lock` file before its checks ran, and kept it: `--out /` (refused by every
command) left `/.lock`, a refused run into a symlinked user folder left one among the user's files, a refused run
into another run's folder overwrote that run's. The lock is now the kernel's, on the folder's own descriptor:
nothing to leave, and it goes when its process dies. A `--video` onto an existing file is refused
(with --replace too, unless this eval's earlier run into the same --out wrote it: tests/test_sixth_pass.py).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from fuzzing import snapshot
from helpers import RUNS, one_line, over

from mjx_pusht.cli import main

@pytest.mark.parametrize("command", RUNS)
def test_out_root_is_refused_and_leaves_nothing_in_it(command, capsys):
    before = sorted(os.listdir("/"))
    for extra in ([], ["--share-out"], ["--replace", "--share-out"]):
        assert main([*RUNS[command], "--out", "/", *extra]) == 1
        one_line(capsys, "--out / is the filesystem's root")
        assert sorted(os.listdir("/")) == before


@pytest.mark.parametrize("command", RUNS)
def test_a_refused_run_into_a_symlinked_users_folder_leaves_it_as_it_was(command, tmp_path, capsys):
    users = tmp_path / "mine"
    (users / "sub").mkdir(parents=True)
    (users / "notes.md").write_text("mine")
    (users / "sub" / "data.csv").write_text("1,2\n")
    os.symlink(users, tmp_path / "link")
    before = snapshot(tmp_path)
    for extra in ([], ["--replace"]):
        assert main([*RUNS[command], "--out", str(tmp_path / "link"), *extra]) == 1
        one_line(capsys, "holds", "never removes")
        assert snapshot(tmp_path) == before


def test_a_finished_run_leaves_no_lock_and_a_refused_one_does_not_touch_it(tmp_path, capsys):
    out = tmp_path / "s"
    assert main([*RUNS["sweep"], "--out", str(out)]) == 0
    capsys.readouterr()
    done = snapshot(out)
    assert ".lock" not in done and "per_seed.parquet" in done
    for command in ("eval", "scene", "demos"):
        for extra in ([], ["--replace"]):
            assert main([*RUNS[command], "--out", str(out), *extra]) == 1
            one_line(capsys, "holds sweep's results")
            assert snapshot(out) == done


def test_a_symlink_loop_as_out_is_one_line(tmp_path, capsys):
    os.symlink(tmp_path / "loop", tmp_path / "loop")
    for command in RUNS:
        assert main([*RUNS[command], "--out", str(tmp_path / "loop")]) == 1
        one_line(capsys, "--out", "loop")
    assert sorted(os.listdir(tmp_path)) == ["loop"]


HOLD = """
import sys, time
from mjx_pusht.io.outputs import claim_out_dir, held_folders
with held_folders():
    claim_out_dir(sys.argv[1], "sweep", {"held": True})
    print("held", flush=True)
    time.sleep(120)
"""


def test_the_lock_is_held_by_the_process_and_goes_with_it(tmp_path, capsys):
    """A run killed with SIGKILL (no handler, no clean-up) leaves no lock behind: the next run goes ahead."""
    out = tmp_path / "busy"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        before = snapshot(out)
        assert ".lock" not in before
        assert main([*RUNS["sweep"], "--out", str(out)]) == 1
        one_line(capsys, "in use by another mjx-pusht run")
        assert snapshot(out) == before
    finally:
        holder.kill()
        holder.wait()
    t0 = time.monotonic()
    assert main([*RUNS["sweep"], "--replace", "--out", str(out)]) == 0, capsys.readouterr().err
    assert time.monotonic() - t0 < 60 and ".lock" not in os.listdir(out)


def test_video_onto_an_existing_file_is_refused_unless_replace(tmp_path, capsys):
    video = tmp_path / "v.gif"
    video.write_bytes(b"a user's picture")
    args = over(RUNS["eval"], "--seeds", "1", "--video", str(video), "--video-size", "32")
    assert main([*args, "--out", str(tmp_path / "o")]) == 1  # a user's file: never, so no hint to pass --replace
    assert "--replace" not in one_line(capsys, f"--video {video} already exists", "no earlier eval")
    assert video.read_bytes() == b"a user's picture" and sorted(os.listdir(tmp_path)) == ["v.gif"]
    assert main([*args, "--out", str(tmp_path / "o"), "--replace"]) == 1  # no run wrote it: --replace or not
    one_line(capsys, f"--video {video} already exists", "no earlier eval")
    assert video.read_bytes() == b"a user's picture" and sorted(os.listdir(tmp_path)) == ["v.gif"]
