"""What the finiteness check of the controller's actions costs the MJX rollout: with it and without it, in one run.

The check (mjx_pusht/backends/actions.py) is a per-row record carried in the compiled scan and read when the
chunk comes back. Two programs of one batch shape are compiled, `check_actions` on and off, and run in turns
(on, off, on, off, ...) so drift in the device's clock or temperature falls on both alike. Two scenarios:

- sweep: the chapter's schedule, one physics step per control step (the check runs every physics step: its
  dearest case);
- eval: the expert on task starts, 10 physics steps per control step (the commands `eval` and `compare` run).

Each variant's rows must equal the other's (a finite action is passed through untouched), or the run says so.

    python -m benchmarks.finite_check --backend mjx-warp --batch 65536 --repeats 5 --out results/h100-finite.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np


def scenarios(max_steps: int) -> dict:
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.controllers import Expert
    from mjx_pusht.task.episode import Episode

    # the eval scenario runs every episode to max_steps (no early end), so both variants step the same work
    return {"sweep": Scenario(),
            "eval": Scenario(controller=Expert(), reset="task", episode=Episode(max_steps=max_steps, terminate=False))}


def measure(name: str, scenario, backend_name: str, batch: int, repeats: int) -> dict:
    from mjx_pusht.backends.factory import make_backend
    from mjx_pusht.task.reset import start_poses

    seeds = np.arange(batch)
    poses = start_poses(seeds, reset=scenario.reset)
    variants = {"check": make_backend(backend_name, scenario, check_actions=True),
                "no_check": make_backend(backend_name, scenario, check_actions=False)}
    first, rows = {}, {}
    for label, backend in variants.items():  # compile and warm up each program
        t0 = time.perf_counter()
        rows[label] = backend.run(seeds, batch=batch, poses=poses)
        first[label] = time.perf_counter() - t0
    times = {label: [] for label in variants}
    for _ in range(repeats):
        for label, backend in variants.items():
            t0 = time.perf_counter()
            backend.run(seeds, batch=batch, poses=poses)
            times[label].append(time.perf_counter() - t0)
    med = {label: statistics.median(t) for label, t in times.items()}
    controller, episode = scenario.driver()
    physics_steps = batch * episode.physics_steps
    a, b = rows["check"], rows["no_check"]
    same = all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
               for f in ("final", "settled", "pusher_final", "gap_max_dev", "finite", "contained"))
    out = {
        "scenario": name, "controller": controller.name, "control_steps": episode.max_steps,
        "physics_steps_per_control_step": episode.frame_skip, "batch": batch, "repeats": repeats,
        "device": variants["check"].device,
        "first_call_seconds": {k: round(v, 3) for k, v in first.items()},
        "run_seconds_median": {k: round(v, 5) for k, v in med.items()},
        "run_seconds_all": {k: [round(t, 5) for t in v] for k, v in times.items()},
        "steps_per_second": {k: round(physics_steps / v, 1) for k, v in med.items()},
        "check_cost_fraction": round(med["check"] / med["no_check"] - 1, 5),
        "rows_identical": bool(same),
    }
    print(f"{name}: check {med['check']:.4f} s, no check {med['no_check']:.4f} s (median of {repeats}): "
          f"cost {out['check_cost_fraction']:+.2%}; rows identical: {same}", flush=True)
    for backend in variants.values():
        backend.close()
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="mjx-warp", help="mjx-warp or mjx-jax (default mjx-warp)")
    p.add_argument("--batch", type=int, default=65536)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--max-steps", type=int, default=300, help="the eval scenario's control steps (default 300)")
    p.add_argument("--scenarios", default="sweep,eval")
    p.add_argument("--out", type=Path, required=True, help="the JSON file to write")
    args = p.parse_args(argv)
    from mjx_pusht.backends.base import versions
    from mjx_pusht.io.banner import tier

    every = scenarios(args.max_steps)
    result = {"what": "MJX rollout with and without the finiteness check of the controller's actions",
              "host": tier(), "backend": args.backend, "versions": versions(), "date": time.strftime("%Y-%m-%d"),
              "scenarios": [measure(n, every[n], args.backend, args.batch, args.repeats)
                            for n in args.scenarios.split(",")]}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
