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


# The picture's rows: which env drew each, as its panels' labels say
PICTURE_ROWS = (("gym_pusht/PushT-v0", "gym-pusht 0.1.8"), ("mjx_pusht/PushT-gym-pusht-v0", "mjx_pusht drop-in"))
SCALE, BAND = 3, 22  # the 96 x 96 images drawn 3x, nearest; the label band above each panel (pixels)
# gym-pusht's reset_to_state (agent x, y, block x, y, angle; pixels), one a column
PICTURE_STATES = ((300, 380, 200, 150, 0.4), (100, 100, 350, 300, -2.0), (400, 200, 224.18, 242.82, 0.7853981633974483),
                  (150, 420, 300, 380, 2.6))


def picture(path: str) -> None:
    """gym-pusht's and the drop-in's 96 x 96 `pixels` of the same four `reset_to_state`s, one row each, every panel
    labelled in the image with the env that drew it and the state's number (a picture copied out of the docs keeps
    saying which row is which)."""
    import gymnasium as gym
    from PIL import Image, ImageDraw, ImageFont

    states = [list(s) for s in PICTURE_STATES]
    side = 96 * SCALE
    img = Image.new("RGB", (side * len(states), (side + BAND) * len(PICTURE_ROWS)), (255, 255, 255))
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default(size=BAND - 6)
    for r, (env_id, name) in enumerate(PICTURE_ROWS):
        env = gym.make(env_id, obs_type="pixels")
        for c, s in enumerate(states):
            frame = Image.fromarray(env.reset(options={"reset_to_state": s})[0])
            top = r * (side + BAND)
            img.paste(frame.resize((side, side), Image.NEAREST), (c * side, top + BAND))
            draw.text((c * side + 4, top + 2), f"{name}, state {c + 1}", fill=(20, 20, 20), font=font)
        env.close()
    img.save(path)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--json", default=None)
    p.add_argument("--picture", default=None, help="write gym-pusht's and the drop-in's 96 x 96 images of the "
                   "same four states side by side (top row gym-pusht, bottom row the drop-in, each panel labelled), "
                   "and stop")
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
