"""Refusals that change nothing, found on review and by the seventh hostile pass (docs/notebook/hostile7.md; what
changed for each: docs/notebook/boundary.md, "After the seventh pass")."""

from __future__ import annotations

import pytest
from fuzzing import snapshot
from helpers import RUNS, one_line

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
