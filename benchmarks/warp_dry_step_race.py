"""The MJX-Warp dry step against a step still in flight (notebook lead5: the CI hang).

    python -m benchmarks.warp_dry_step_race --n 200

Sends a 4-world MJX-Warp step on the CPU without waiting for it, then runs `warp_kernels.scene_modules` (the dry
step every new MJX-Warp env makes, which swaps wp.launch and wp.capture_while for recorders, process-wide) while
it may still run, N times. Before the dry step held Warp's FFI callback lock, 5 of 6 runs of up to 200 ended in a
hang (the step never finishes: exit 3, every thread's stack printed) or a crash; after it, none in 750.
"""

from __future__ import annotations

import argparse
import faulthandler
import os
import threading


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=200, help="steps sent, each with a dry step behind it")
    p.add_argument("--timeout", type=float, default=30, help="seconds a step may take before it counts as hung")
    args = p.parse_args(argv)

    import gymnasium as gym
    import jax.numpy as jnp
    import numpy as np

    import mjx_pusht  # noqa: F401  (registers the envs)
    from mjx_pusht.backends.warp_kernels import scene_modules

    envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=4, backend="mjx-warp", array_type="jax")
    model = envs.unwrapped._env.model if hasattr(envs.unwrapped, "_env") else envs.unwrapped.model
    action = jnp.full((4, 2), 0.3)
    envs.reset(seed=7)
    np.asarray(envs.step(action)[0])
    for i in range(args.n):
        envs.reset(seed=7)
        obs = envs.step(action)[0]  # sent, not waited for
        scene_modules(model)  # what the next env's precompile does, while the step may still run
        got = []
        reader = threading.Thread(target=lambda: got.append(np.asarray(obs)), daemon=True)
        reader.start()
        reader.join(args.timeout)
        if reader.is_alive():
            print(f"hang at step {i}: the step never finished", flush=True)
            faulthandler.dump_traceback(all_threads=True)
            os._exit(3)  # the hung XLA thread would keep the interpreter from exiting
    print(f"{args.n} steps, each with a dry step behind it: none hung", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
