"""The gym-pusht expert's success on gym-pusht's task: on the drop-in (MuJoCo C) and in gym-pusht itself (pymunk).

    python -m benchmarks.expert_gym_pusht [--dropin 4096] [--gym-pusht 1000] [--first-seed 1000000000]
        [--workers 2] [--json benchmarks/results/cpu-expert-gym-pusht.json]

Both sides start seed s where gym-pusht's `reset(seed=s)` does and run the expert
(task/expert_gym_pusht.ExpertGymPusht) closed loop on their own observations for up to 300 control steps,
an episode ending at its first success (coverage > 0.95, gym-pusht's `is_success`). The drop-in runs as one
batch on the CPU backend; gym-pusht runs gym_pusht.envs.pusht.PushTEnv, one env a process over `--workers`
(the pattern of benchmarks/dropin_fidelity.py). Per side: the success rate with its 95% Wilson interval,
the median and 90th-percentile steps to success, the wall time, and every failed episode (its start, where
the block ended, its best coverage), so that failures are looked at one by one, not averaged away.
Held-out seeds start at 1,000,000,000 by default (the expert was tuned on seeds below 2,048).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np

STEPS = 300


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95% Wilson score interval of k successes in n trials."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    mid, half = p + z * z / (2 * n), z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return ((mid - half) / (1 + z * z / n), (mid + half) / (1 + z * z / n))


class GymPushtExpert:
    """The expert as a gym-pusht driver: its observation (pixels) to the world frame, its target back to pixels."""

    def __init__(self, seed: int, **params):
        from mjx_pusht.task.controllers import seed_key
        from mjx_pusht.task.expert_gym_pusht import ExpertGymPusht

        self.ctrl, self.key = ExpertGymPusht(**params), seed_key([seed])
        self.carry = self.ctrl.init(self.key)

    def __call__(self, obs, k):
        from mjx_pusht.model import gym_pusht as frame
        from mjx_pusht.task.rules import observe

        agent = frame.to_world(np.asarray(obs[None, 0:2], np.float64))
        tee = frame.pose_to_world(np.asarray(obs[None, 2:4], np.float64), np.asarray(obs[None, 4], np.float64))
        target, self.carry = self.ctrl.act(self.carry, observe(agent, tee), k, self.key)
        return frame.to_px(target)[0]


def run_gym_pusht(seeds, params: dict | None = None) -> dict:
    """gym-pusht 0.1.8 itself: each seed's `reset(seed=s)`, the expert for up to STEPS steps, ending at is_success."""
    from gym_pusht.envs.pusht import PushTEnv

    env = PushTEnv(obs_type="state")
    n = len(seeds)
    steps, best, final = np.zeros(n, np.int64), np.zeros(n), np.zeros((n, 3))
    starts = np.zeros((n, 5))
    for i, seed in enumerate(seeds):
        obs, _ = env.reset(seed=int(seed))
        starts[i] = obs
        drive = GymPushtExpert(int(seed), **(params or {}))
        for k in range(STEPS):
            obs, _, terminated, _, info = env.step(np.asarray(drive(obs, k), np.float64))
            best[i] = max(best[i], info["coverage"])
            if info["is_success"]:
                steps[i] = k + 1
                break
        final[i] = obs[2:5]
    return {"steps_to_success": steps, "best_coverage": best, "final_px": final, "start_px": starts}


def _part(args):
    return run_gym_pusht(*args)


def gym_pusht_pool(seeds, workers: int, params: dict | None = None) -> dict:
    if workers <= 1:
        return run_gym_pusht(seeds, params)
    import multiprocessing

    parts = [(seeds[i], params) for i in np.array_split(np.arange(len(seeds)), workers)]
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        outs = pool.map(_part, parts)
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def run_dropin(seeds, params: dict | None = None) -> dict:
    """The drop-in on the CPU backend (MuJoCo C), one batch: the same task, its own physics."""
    from mjx_pusht import Scenario, SceneSpec, make_backend
    from mjx_pusht.model import gym_pusht as frame
    from mjx_pusht.task.episode import Episode
    from mjx_pusht.task.expert_gym_pusht import ExpertGymPusht

    sc = Scenario(SceneSpec(variant="gym-pusht"), reset="gym-pusht", controller=ExpertGymPusht(**(params or {})),
                  episode=Episode(max_steps=STEPS, end_covered_start=False))
    r = make_backend("cpu", sc).run(np.asarray(seeds, np.int64))
    ep = r.episode
    succ = np.asarray(ep["success"], bool)
    origin, angle = frame.pose_to_px(np.asarray(r.final, np.float64))
    return {"steps_to_success": np.where(succ, np.asarray(ep["steps_to_success"]), 0),
            "best_coverage": np.asarray(ep["best_coverage"], np.float64),
            "final_px": np.concatenate([origin, angle[:, None]], -1)}


def summary(seeds, out: dict, seconds: float) -> dict:
    from mjx_pusht.model.gym_pusht import reset_state

    steps = out["steps_to_success"]
    ok = steps > 0
    k, n = int(ok.sum()), len(seeds)
    lo, hi = wilson(k, n)
    failed = [{"seed": int(seeds[i]), "start_px": [round(float(v), 2) for v in reset_state(int(seeds[i]))],
               "final_px": [round(float(v), 2) for v in out["final_px"][i]],
               "best_coverage": round(float(out["best_coverage"][i]), 4)} for i in np.flatnonzero(~ok)]
    return {"episodes": n, "successes": k, "rate": k / n, "interval95": [round(lo, 4), round(hi, 4)],
            "steps_median": float(np.median(steps[ok])) if k else None,
            "steps_p90": float(np.percentile(steps[ok], 90)) if k else None,
            "seconds": round(seconds, 1), "failed": failed}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--dropin", type=int, default=4096, help="episodes on the drop-in (0: none)")
    p.add_argument("--gym-pusht", type=int, default=1000, help="episodes in gym-pusht itself (0: none)")
    p.add_argument("--first-seed", type=int, default=1_000_000_000, help="seeds first-seed, first-seed + 1, ...")
    p.add_argument("--workers", type=int, default=1, help="processes running gym-pusht")
    p.add_argument("--params", default="{}", help="the expert's parameters as JSON (tuning), e.g. '{\"gap\": 6}'")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    params = json.loads(args.params)
    rows = {}
    for side, n in (("dropin", args.dropin), ("gym_pusht", args.gym_pusht)):
        if n <= 0:
            continue
        seeds = np.arange(args.first_seed, args.first_seed + n, dtype=np.int64)
        t0 = time.perf_counter()
        out = run_dropin(seeds, params) if side == "dropin" else gym_pusht_pool(seeds, args.workers, params)
        rows[side] = summary(seeds, out, time.perf_counter() - t0)
        r = rows[side]
        print(f"{side}: {r['successes']}/{r['episodes']} = {100 * r['rate']:.2f}% (95% {100 * r['interval95'][0]:.2f}-"
              f"{100 * r['interval95'][1]:.2f}%), steps median {r['steps_median']}, p90 {r['steps_p90']}, "
              f"{r['seconds']} s; failed seeds {[f['seed'] for f in r['failed']]}", flush=True)
    if args.json:
        from mjx_pusht.backends.base import versions

        out = {"command": "python -m benchmarks.expert_gym_pusht " + " ".join(argv if argv is not None else sys.argv[1:]),
               "device": f"CPU, {os.cpu_count()} cores ({platform.processor() or platform.machine()})",
               "host": platform.node(), "date": time.strftime("%Y-%m-%d"), "versions": versions(),
               "params": params, "first_seed": args.first_seed, "sides": rows}
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
