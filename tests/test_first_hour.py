"""What a newcomer reads in the first hour says what is true: the viewer command a sweep prints runs, a summary
with no success says so in words."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from mjx_pusht.cli.commands import main


def test_the_sweeps_rerun_hint_is_a_command_that_runs_here(tmp_path):
    """The printed `open it with: CMD PATH` names a viewer that exists where a venv's user is: the one beside this
    Python when `rerun` on PATH is not it (a bare `rerun` was printed where only .venv/bin/rerun existed)."""
    r = subprocess.run([sys.executable, "-m", "mjx_pusht", "sweep", "--seeds", "2", "--backend", "cpu", "--out",
                        str(tmp_path / "s"), "--no-progress"], capture_output=True, text=True,
                       env={**os.environ, "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    line = next(x for x in r.stdout.splitlines() if "open it with:" in x)
    exe, path = line.split("open it with: ")[1].rsplit(" ", 1)
    assert Path(path) == tmp_path / "s" / "sweep.rrd" and Path(path).is_file()
    assert exe == str(Path(sys.executable).parent / "rerun")
    v = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=120)
    assert v.returncode == 0 and "rerun" in v.stdout.lower()


def test_an_eval_with_no_success_says_so_instead_of_none(tmp_path, capsys):
    """The zero controller never moves the T onto the target in 5 steps: the line says no episode succeeded, and
    summary.json keeps null (JSON's none), not a made-up number."""
    out = tmp_path / "e"
    assert main(["eval", "--seeds", "2", "--backend", "cpu", "--controller", "zero", "--max-steps", "5",
                 "--out", str(out), "--no-rerun", "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_success"] == 0 and summary["median_steps_to_success"] is None
    said = capsys.readouterr().out
    assert "median steps to success - (no episode succeeded)" in said and "None" not in said


def test_an_eval_with_successes_prints_their_median_steps(tmp_path, capsys):
    out = tmp_path / "e"
    assert main(["eval", "--seeds", "2", "--reset", "chapter", "--backend", "cpu", "--out", str(out), "--no-rerun",
                 "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_success"] == 2
    assert f"median steps to success {summary['median_steps_to_success']:g};" in capsys.readouterr().out
