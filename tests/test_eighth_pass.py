"""The eighth hostile pass's findings, each run again as written (docs/notebook/hostile8.md; what changed for each:
docs/notebook/boundary.md, "After the eighth pass")."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from helpers import ENV

from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.wrappers import AutoReset
from mjx_pusht.errors import MjxPushtError

SIGINT_IN_THE_GL_PROBE = """
import ctypes.util, os, signal
real = ctypes.util.find_library
def find_library(name):  # the GL probe's ldconfig, interrupted
    os.kill(os.getpid(), signal.SIGINT)
    for _ in range(10000):  # bytecodes for the handler to run in
        pass
    return real(name)
ctypes.util.find_library = find_library
"""


def test_ctrl_c_in_the_gl_probe_is_the_one_line(tmp_path):
    """TRACEBACK (eighth pass): SIGINT 0.03-0.05 s into `eval` was Python's KeyboardInterrupt traceback, once inside
    ctypes.util's ldconfig: the package probed for EGL before it set its import-time handler. It sets it first."""
    (tmp_path / "sitecustomize.py").write_text(SIGINT_IN_THE_GL_PROBE)
    env = {k: v for k, v in ENV.items() if k not in ("MUJOCO_GL", "DISPLAY")}  # so that the probe runs
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(tmp_path), ENV.get("PYTHONPATH", "")) if p)
    r = subprocess.run([sys.executable, "-m", "mjx_pusht", "tree"], capture_output=True, text=True, env=env,
                       preexec_fn=lambda: __import__("signal").signal(2, __import__("signal").SIG_DFL))
    assert r.returncode == 130, r.stderr[-2000:]
    assert r.stderr.strip() == "mjx-pusht: interrupted before the command started: nothing was written", r.stderr


def test_autoreset_takes_an_env_and_its_own_states():
    """TRACEBACK (eighth pass): AutoReset(AutoReset(env)) was taken, then its reset raised AttributeError; its step
    given the bare env's state raised TypeError; refill given another AutoReset's state raised AttributeError."""
    env = PushTEnv()
    bare = env.reset(np.arange(3))
    with pytest.raises(MjxPushtError, match="AutoReset's env must be a functional PushTEnv"):
        AutoReset(AutoReset(env))
    with pytest.raises(MjxPushtError, match="AutoReset.step before its reset"):
        AutoReset(env).step(bare, np.zeros((3, 2)))
    wrapped = AutoReset(env)
    state = wrapped.reset(np.arange(3))
    with pytest.raises(MjxPushtError, match="takes a state from this AutoReset's own reset"):
        wrapped.step(bare, np.zeros((3, 2)))
    with pytest.raises(MjxPushtError, match="takes a state from this AutoReset's own reset .of its 3 rows"):
        wrapped.refill(AutoReset(env).reset(np.arange(2)))
    state = wrapped.refill(wrapped.step(state, np.zeros((3, 2))))  # its own: steps as before
    assert np.array_equal(state.step, [1, 1, 1])


@pytest.mark.parametrize("kw", [{"contacts_per_world": 4}, {"rows_per_world": 4}])
def test_the_cpu_functional_env_refuses_mjxs_buffer_sizes(kw):
    """SILENT (eighth pass): PushTEnv(backend="cpu", contacts_per_world=4) was taken and ignored (MuJoCo C sizes its
    own), while graph_mode and raster were refused there."""
    with pytest.raises(MjxPushtError, match="size MJX's buffers"):
        PushTEnv(backend="cpu", **kw)
