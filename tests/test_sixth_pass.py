"""The sixth hostile pass's findings, each run again as written (docs/notebook/hostile6.md; what changed for each:
docs/notebook/boundary.md, "After the sixth pass")."""

from __future__ import annotations

import os

from fuzzing import snapshot
from helpers import RUNS, one_line

from mjx_pusht.cli import main

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
