"""Errors: bad input is one line and a non-zero exit; a bug inside the library keeps its traceback."""

from __future__ import annotations

import subprocess
import sys

import pytest
from helpers import cli

from mjx_pusht.errors import MjxPushtError


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def test_a_value_error_from_a_bug_inside_the_library_prints_its_traceback():
    # a genuine ValueError raised deep in the library (here: the tree reader) is a bug, not bad input
    r = _python("import sys, mjx_pusht.model.tree as t\n"
                "def broken(*a, **k): raise ValueError('a bug, not bad input')\n"
                "t.read_tree = broken\n"
                "from mjx_pusht.cli import main\n"
                "sys.exit(main(['tree']))")
    assert r.returncode != 0
    assert "Traceback (most recent call last)" in r.stderr and "ValueError: a bug, not bad input" in r.stderr


@pytest.mark.parametrize("argv", [
    ["sweep", "--backend", "nope"],
    ["sweep", "--seeds", "5:5"],
    ["sweep", "--steps", "0"],
    ["eval", "--controller", "no.such.module:fn", "--seeds", "2", "--backend", "cpu"],
    ["scene", "--break", "nope"],
    ["eval", "--video", "x.avi", "--seeds", "2", "--backend", "cpu"],
])
def test_each_user_facing_error_is_one_line_and_a_non_zero_exit(tmp_path, argv):
    r = cli(*argv, "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("mjx-pusht: error:"), r.stderr


def test_every_error_the_library_raises_for_bad_input_shares_one_base():
    from mjx_pusht.backends.base import BackendError
    from mjx_pusht.backends.warp import BufferOverflow
    from mjx_pusht.render.pixels import PixelsError
    from mjx_pusht.io.outputs import OutputError
    from mjx_pusht.io.video import VideoError
    from mjx_pusht.model.params import ParamError
    from mjx_pusht.model.tree import TreeMismatch
    from mjx_pusht.study.distributed import DistributedError
    from mjx_pusht.study.seeds import SeedSpecError
    from mjx_pusht.study.sweep import ResumeError
    from mjx_pusht.task.controllers import ControllerError

    for cls in (BackendError, BufferOverflow, PixelsError, OutputError, VideoError, ParamError, TreeMismatch,
                DistributedError, SeedSpecError, ResumeError, ControllerError):
        assert issubclass(cls, MjxPushtError), cls
    # and a library call with a bad value raises it (a ValueError too, for callers that catch those)
    from mjx_pusht.task.episode import Episode

    with pytest.raises(MjxPushtError, match="max_steps"):
        Episode(max_steps=0)
    with pytest.raises(ValueError):
        Episode(max_steps=0)


def test_the_collider_table_without_warp_lang_is_one_line_naming_the_extra():
    # sys.modules[name] = None makes `import warp` fail as it does where warp-lang is not installed
    r = _python("import sys; sys.modules['warp'] = None\n"
                "from mjx_pusht.cli import main\n"
                "sys.exit(main(['tree', '--colliders']))")
    assert r.returncode == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "pip install 'mjx-pusht[warp]'" in lines[0], r.stderr
