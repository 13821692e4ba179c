"""The gymnasium vector env (state observations) stepped as a user steps it: control steps per second and GPU memory.

    python -m benchmarks.env_step --envs 4096,16384,65536 [--steps 30] [--json out.json]

Each batch size runs in its own process (a crash at one size, such as an allocation failure, is
recorded, not fatal): `gym.make_vec("mjx_pusht/PushT-v0", num_envs=N, backend="mjx-warp")`, reset,
3 warm-up steps (compile), then `--steps` steps of sampled actions, timed. The figure is N x steps
/ seconds; GPU memory is JAX's peak bytes in use on the device. This is the measurement issue 20's
table was made with (gymnasium's `make_vec`, 30 steps after 3 warm-up).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

ONE = r"""
import json, sys, time, numpy as np, gymnasium as gym, mjx_pusht, jax
n, steps = int(sys.argv[1]), int(sys.argv[2])
envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=n, backend="mjx-warp", obs_type="state")
envs.reset(seed=0)
rng = np.random.default_rng(0)
acts = [rng.uniform(-1, 1, (n, 2)).astype(np.float32) for _ in range(steps + 3)]
for a in acts[:3]:
    envs.step(a)
t0 = time.perf_counter()
for a in acts[3:]:
    obs, *_ = envs.step(a)
dt = time.perf_counter() - t0
stats = jax.devices()[0].memory_stats() or {}
print(json.dumps({"envs": n, "steps": steps, "seconds": dt, "control_steps_per_s": n * steps / dt,
                  "ms_per_step": 1000 * dt / steps, "peak_bytes_in_use": stats.get("peak_bytes_in_use")}))
"""


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--envs", default="4096,16384,65536")
    p.add_argument("--steps", type=int, default=30)
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    rows = []
    for n in (int(x) for x in args.envs.split(",")):
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", ONE, str(n), str(args.steps)], capture_output=True, text=True)
        if r.returncode == 0:
            row = json.loads(r.stdout.strip().splitlines()[-1])
        else:
            last = (r.stderr.strip().splitlines() or ["?"])[-1]
            row = {"envs": n, "error": last[:300]}
        row["process_seconds"] = time.perf_counter() - t0
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"rows": rows}, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
