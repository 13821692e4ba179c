"""The gym-pusht drop-in against gym-pusht itself, one env each, on this machine's CPU.

    python -m benchmarks.gym_pusht [--steps 300] [--json benchmarks/results/cpu-gym-pusht.json]
    python -m benchmarks.gym_pusht --picture outputs/reports/gym-pusht-side-by-side.png

For each obs_type (state, pixels_agent_pos): `gym.make(id, obs_type=...)` for gym-pusht 0.1.8
(pymunk) and for `mjx_pusht/PushT-gym-pusht-v0` (MuJoCo C), reset with seed 0, then `steps`
control steps of the same random pixel targets (an episode that ends is reset), timed after 10
warm-up steps. Control steps per second, in one process, side by side; and `push_divergence`: the
same 40-step push in both physics from seeds 0-3, how far apart the blocks end. The batched drop-in on a
GPU is `python -m benchmarks.env_loop --obs pixels --cases dropin_numpy,dropin_torch`.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time


def measure(env_id: str, obs_type: str, steps: int) -> float:
    import gymnasium as gym
    import numpy as np

    env = gym.make(env_id, obs_type=obs_type)
    env.reset(seed=0)
    acts = np.random.default_rng(0).uniform(0, 512, (steps + 10, 2))
    for i in range(10):
        env.step(acts[i])
    t0 = time.perf_counter()
    for a in acts[10:]:
        *_, te, tr, _ = env.step(a)
        if te or tr:
            env.reset()
    return steps / (time.perf_counter() - t0)


def push_divergence(seeds=range(4), steps: int = 40) -> list[dict]:
    """The same push in both physics: from gym-pusht's start for each seed, `steps` targets at the block's
    starting origin; how far apart the blocks end (pixels, radians)."""
    import gymnasium as gym
    import numpy as np

    out = []
    for seed in seeds:
        ends = []
        for env_id in ("gym_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"):
            env = gym.make(env_id, obs_type="state")
            o, _ = env.reset(seed=seed)
            target = o[2:4].copy()
            for _ in range(steps):
                o, *_ = env.step(target)
            ends.append(o)
        d = ends[1] - ends[0]
        out.append({"seed": seed, "block_px_apart": float(np.hypot(d[2], d[3])),
                    "angle_apart_rad": float(abs((d[4] + np.pi) % (2 * np.pi) - np.pi)),
                    "agent_px_apart": float(np.hypot(d[0], d[1]))})
    return out


def picture(path: str) -> None:
    import gymnasium as gym
    import numpy as np
    from PIL import Image

    states = [[300, 380, 200, 150, 0.4], [100, 100, 350, 300, -2.0], [400, 200, 224.18, 242.82, np.pi / 4],
              [150, 420, 300, 380, 2.6]]
    rows = []
    for env_id in ("gym_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"):
        env = gym.make(env_id, obs_type="pixels")
        rows.append(np.concatenate([env.reset(options={"reset_to_state": s})[0] for s in states], axis=1))
    img = Image.fromarray(np.concatenate(rows, axis=0))
    img.resize((img.width * 3, img.height * 3), Image.NEAREST).save(path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--json", default=None)
    p.add_argument("--picture", default=None, help="write gym-pusht's and the drop-in's 96 x 96 images of the "
                   "same four states side by side (top row gym-pusht, bottom row the drop-in), and stop")
    args = p.parse_args(argv)
    import gym_pusht  # noqa: F401

    import mjx_pusht  # noqa: F401

    if args.picture:
        picture(args.picture)
        return 0

    rows = []
    for obs_type in ("state", "pixels_agent_pos"):
        row = {"obs_type": obs_type, "steps": args.steps}
        for name, env_id in (("gym_pusht", "gym_pusht/PushT-v0"), ("drop_in", "mjx_pusht/PushT-gym-pusht-v0")):
            row[name + "_control_steps_per_s"] = measure(env_id, obs_type, args.steps)
        rows.append(row)
        print(json.dumps(row), flush=True)
    push = push_divergence()
    print(json.dumps({"push_divergence": push}), flush=True)
    if args.json:
        from mjx_pusht.backends.base import versions

        out = {"command": "python -m benchmarks.gym_pusht " + " ".join(argv if argv is not None else sys.argv[1:]),
               "device": f"CPU, {os.cpu_count()} cores ({platform.processor() or platform.machine()})",
               "host": platform.node(), "date": time.strftime("%Y-%m-%d"), "versions": versions(), "rows": rows,
               "push_divergence": push}
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
