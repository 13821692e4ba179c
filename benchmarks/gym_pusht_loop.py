"""A committed policy in a plain gym-pusht loop, the way the docs tell a user to run it, beside `eval --backend gym-pusht`.

    python -m benchmarks.gym_pusht_loop --policy outputs/reports/train/ppo-state-gym-pusht-h200/seed-0/policy.msgpack \
        --seeds 2000000000:2000001000 [--eval] [--json benchmarks/results/cpu-gym-pusht-loop-ppo-s0.json]

The loop is gym-pusht's public door and nothing else: `gym.make("gym_pusht/PushT-v0", obs_type=policy.obs_type)`,
`reset(seed=s)`, then `step(policy(obs))` until gym-pusht says terminated or truncated (its own 300-step limit),
success read from gym-pusht's `info["is_success"]`. `--eval` also runs `mjx-pusht eval --task gym-pusht --backend
gym-pusht` on the same seeds (in a subprocess, as a user runs it) and compares the two episode for episode: success,
steps to success, final block pose. Seeds spread over a process per core.
"""

from __future__ import annotations

import os

# one BLAS thread a process (set before NumPy loads): a policy's 32-row products took 38 ms each with OpenBLAS's
# threads fighting the other workers for this 2-core CPU, 0.5 ms with one
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np


def plain_loop(policy_path: str, seeds) -> list[dict]:
    """Each seed's episode in gym-pusht's own loop through GymPushtPolicy: success, steps, final observation."""
    import gym_pusht  # noqa: F401  (registers gym_pusht/PushT-v0)
    import gymnasium as gym

    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    policy = GymPushtPolicy(policy_path)
    env = gym.make("gym_pusht/PushT-v0", obs_type=policy.obs_type)
    rows = []
    for seed in seeds:
        obs, info = env.reset(seed=int(seed))
        policy.reset(seed=int(seed))  # a sampling policy's draws keyed by the episode's seed, as eval keys them
        steps, success, first = 0, False, None
        while True:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            steps += 1
            if info["is_success"] and first is None:
                success, first = True, steps
            if terminated or truncated:
                break
        block = env.unwrapped.block
        rows.append({"seed": int(seed), "success": success, "steps_to_success": first, "length": steps,
                     "block": [*map(float, block.position), float(block.angle)]})
    env.close()
    return rows


def run_eval(policy_path: str, lo: int, hi: int) -> list[dict]:
    """`mjx-pusht eval --task gym-pusht --backend gym-pusht` on seeds lo:hi, as a user runs it; its per-episode rows."""
    import pyarrow.parquet as pq

    from mjx_pusht.model import gym_pusht as frame

    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "mjx_pusht", "eval", "--task", "gym-pusht", "--backend", "gym-pusht",
               "--controller", f"policy:{policy_path}", "--seeds", f"{lo}:{hi}", "--no-rerun", "--out", f"{tmp}/e"]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        t = pq.read_table(f"{tmp}/e/per_episode.parquet").to_pydict()
    final = np.stack([t["tee_final_x"], t["tee_final_y"], t["tee_final_yaw"]], axis=-1)
    origin, angle = frame.pose_to_px(final)
    return [{"seed": int(s), "success": bool(ok), "steps_to_success": None if not ok else int(n),
             "block": [float(origin[i, 0]), float(origin[i, 1]), float(angle[i])]}
            for i, (s, ok, n) in enumerate(zip(t["seed"], t["success"], t["steps_to_success"]))]


def summary(rows) -> dict:
    ok = np.array([r["success"] for r in rows])
    steps = [r["steps_to_success"] for r in rows if r["success"]]
    return {"episodes": len(rows), "successes": int(ok.sum()), "success": float(ok.mean()) if len(ok) else None,
            "median_steps_to_success": float(np.median(steps)) if steps else None}


def compare(loop, ev) -> dict:
    """Episode for episode: the same verdict, the same steps to success, the block's final pose (px, rad mod 2 pi)."""
    by = {r["seed"]: r for r in ev}
    verdict = [r["seed"] for r in loop if by[r["seed"]]["success"] != r["success"]]
    steps = [r["seed"] for r in loop if by[r["seed"]]["steps_to_success"] != r["steps_to_success"]]
    dx = [np.hypot(*np.subtract(r["block"][:2], by[r["seed"]]["block"][:2])) for r in loop]
    da = [abs((r["block"][2] - by[r["seed"]]["block"][2] + np.pi) % (2 * np.pi) - np.pi) for r in loop]
    return {"verdict_differs": verdict, "steps_differ": steps, "block_px_apart_max": float(max(dx)),
            "angle_apart_rad_max": float(max(da))}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", required=True)
    ap.add_argument("--seeds", default="2000000000:2000000200", help="LO:HI")
    ap.add_argument("--eval", action="store_true", help="also run `eval --backend gym-pusht` and compare")
    ap.add_argument("--workers", type=int, default=len(os.sched_getaffinity(0)))
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    lo, hi = map(int, a.seeds.split(":"))
    seeds = np.arange(lo, hi)
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.workers) as pool:
        parts = pool.map(plain_loop, [a.policy] * a.workers, np.array_split(seeds, a.workers))
        loop = [r for part in parts for r in part]
    out = {"policy": a.policy, "seeds": a.seeds, "machine": f"{platform.machine()}, {os.cpu_count()} cores",
           "gym_pusht": _version("gym-pusht"), "plain_loop": summary(loop),
           "plain_loop_s": round(time.perf_counter() - t0, 1)}
    if a.eval:
        t0 = time.perf_counter()
        ev = run_eval(a.policy, lo, hi)
        out |= {"eval_backend": summary(ev), "eval_s": round(time.perf_counter() - t0, 1), "compare": compare(loop, ev)}
    out["failed_seeds_plain_loop"] = [r["seed"] for r in loop if not r["success"]]
    print(json.dumps(out, indent=1))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out | {"episodes": loop}, f, indent=1)


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)


if __name__ == "__main__":
    main()
