"""Probe MJX-Warp on a multi-GPU host: one device, then sharded over all (faulthandler on)."""
import faulthandler
import sys
import time

import numpy as np

faulthandler.enable()
import jax  # noqa: E402

from mjx_pusht.backends.mjx import MjxBackend  # noqa: E402
from mjx_pusht.scenario import Scenario  # noqa: E402

n = int(sys.argv[1]) if len(sys.argv) > 1 else 4096
for devs in ([jax.devices()[0]], jax.devices()):
    b = MjxBackend(Scenario(), "warp", devices=devs)
    t0 = time.perf_counter()
    r = b.run(np.arange(n))
    print(b.device, n, "first call", round(time.perf_counter() - t0, 2), "s; rigid", r.rigid.mean(), flush=True)
