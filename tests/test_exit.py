"""No hang at exit: the README's tour, piece 2 (an MJX-Warp functional env stepped and never read), exits on a
CPU-only machine. It used to finish its step and then never exit: Warp's FFI callbacks need the GIL, which a
finalizing interpreter never gives back (backends/warp.py: finish_before_exit)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from mjx_pusht.backends.warp import warp_available

TOUR = textwrap.dedent("""
    import numpy as np
    from mjx_pusht.envs.functional import PushTEnv
    env = PushTEnv(backend="mjx-warp", reset_kind="task", action_type="velocity")
    state = env.reset(np.arange(16))
    state = env.step(state, np.zeros((16, 2), np.float32))
    print("stepped", flush=True)
""")


@pytest.mark.slow  # compiles Warp's kernels on the CPU: ~20 s on the project's 2-core machine
@pytest.mark.skipif(not warp_available(), reason="needs the [warp] extra")
def test_the_tours_warp_step_exits_when_the_script_ends():
    r = subprocess.run([sys.executable, "-c", TOUR], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "stepped" in r.stdout, r.stderr[-2000:]
