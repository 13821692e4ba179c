"""Ctrl-C or SIGTERM at any moment of a command, its imports included: one line, exit 130 or 143, no traceback.

Before: a Ctrl-C in the first seconds of `sweep` or `eval` (while NumPy, MuJoCo, JAX or pyarrow load) was a
KeyboardInterrupt traceback, or `ImportError: initialization failed` when it landed inside an extension's import;
a SIGTERM ended the process with no word.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from helpers import ENV


def _child_default_signals():
    os.setsid()  # its own group, as a terminal's foreground job; pytest's SIGINT handling is not inherited
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _signalled(args, sig, after: float, out) -> subprocess.CompletedProcess:
    p = subprocess.Popen([sys.executable, "-m", "mjx_pusht", *args, "--out", str(out)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=ENV, preexec_fn=_child_default_signals)
    time.sleep(after)
    p.send_signal(sig)
    stdout, stderr = p.communicate(timeout=120)
    return subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)


# long enough that the last signal (3.0 s) lands in the work on a fast machine: CI's runner finished 2,000 seeds in
# 2.6 s and the signal met the interpreter's exit, after every file was written (exit -15, no line)
SWEEP = ("sweep", "--backend", "cpu", "--seeds", "20000", "--no-rerun", "--no-progress")
EVAL = ("eval", "--backend", "cpu", "--seeds", "200", "--no-rerun", "--no-progress")


@pytest.mark.slow  # a process started per case, 5 s each on this CPU
@pytest.mark.parametrize("args,sig,after", [
    # while the package itself imports (its first line runs about 0.1 s after the interpreter starts, later on a
    # loaded machine: a signal before it meets Python's own startup, which no code of the package's can answer)
    (SWEEP, signal.SIGINT, 0.8),
    (EVAL, signal.SIGINT, 1.2),  # while the command's modules import (or its first episodes)
    (SWEEP, signal.SIGINT, 2.5),
    (EVAL, signal.SIGTERM, 1.0),
    (SWEEP, signal.SIGTERM, 3.0),
])
def test_a_signal_at_any_moment_is_one_line_and_its_exit_status(args, sig, after, tmp_path):
    r = _signalled(args, sig, after, tmp_path / "out")
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 128 + sig, (args[0], sig, after, r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "Error" not in r.stderr, r.stderr[-2000:]
    # one line: main's, or the batch's own (which names the chunks kept and how to resume)
    assert len(lines) == 1 and ("interrupted" in lines[0] or "terminated" in lines[0]), (args[0], sig, after,
                                                                                         r.stderr[-2000:])
    assert not (tmp_path / "out" / ".lock").exists()
