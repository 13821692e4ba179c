"""What each `--randomize` parameter does on each task, measured on MuJoCo C (docs/task.md's table).

    python -m benchmarks.randomize_meaning [--seeds 32] [--first-seed 1000000000]

Per task and parameter, every episode at a fixed factor (`randomize={name: (f, f)}`, a range's end): the expert's
success on held-out task seeds (300 control steps) and its median control steps to success; for the pusher's gains,
how far the pusher moves in its first control step from seed 0's start (chapter: 0.5 m/s commanded; gym-pusht: a
target 50 mm ahead in x). Prints one line each.
"""

from __future__ import annotations

import argparse

import numpy as np

ENDS = {"chapter": {"tee_mass": (0.5, 2.0), "tee_damping": (0.5, 1.5), "tee_frictionloss": (0.1, 2.0),
                    "kv": (0.5, 2.0)},
        "gym-pusht": {"kp": (0.5, 2.0), "kv": (0.5, 2.0)}}
GAINS = (("chapter", "kv"), ("gym-pusht", "kp"), ("gym-pusht", "kv"))


def expert(task: str, rz: dict, seeds: np.ndarray) -> tuple[float, float | None]:
    from mjx_pusht.backends.cpu import run_cpu
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.tasks import get

    t = get(task)
    sc = Scenario(t.scene(), reset=t.check_reset(None), controller=t.controller("expert"), episode=t.episode(300),
                  randomize=rz)
    e = run_cpu(sc, seeds).episode
    steps = e["steps_to_success"][e["success"]]
    return float(e["success"].mean()), float(np.median(steps)) if len(steps) else None


def first_step_mm(task: str, name: str, f: float) -> float:
    from mjx_pusht.envs.functional import PushTEnv

    env = PushTEnv.for_task(task, "cpu", randomize={name: (f, f)})
    s = env.reset(np.array([0]))
    p0 = np.array(s.obs["state"][0, :2])
    a = np.array([[0.5, 0.0]]) if task == "chapter" else (p0 + [0.05, 0.0])[None]
    return float(env.step(s, a).obs["state"][0, 0] - p0[0]) * 1000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=32)
    ap.add_argument("--first-seed", type=int, default=1_000_000_000)
    args = ap.parse_args()
    seeds = args.first_seed + np.arange(args.seeds, dtype=np.int64)
    for task, names in ENDS.items():
        print(task, "own physics: expert success, median steps", expert(task, {}, seeds), flush=True)
        for name, ends in names.items():
            for f in ends:
                print(task, name, f"x{f:g}: expert success, median steps", expert(task, {name: (f, f)}, seeds),
                      flush=True)
    for task, name in GAINS:
        moved = [round(first_step_mm(task, name, f), 2) for f in (0.5, 1.0, 2.0)]
        print(task, name, "x0.5, x1, x2: the pusher's first control step (mm)", moved, flush=True)


if __name__ == "__main__":
    main()
