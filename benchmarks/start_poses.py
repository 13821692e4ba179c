"""Start poses for a million seeds on one core: the vectorised generators against one default_rng per seed.

    python -m benchmarks.start_poses          # writes benchmarks/results/<tier>-start-poses.json
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from mjx_pusht.backends.base import versions
from mjx_pusht.io.banner import tier as tier_name
from mjx_pusht.task.reset import start_poses, start_state

RESULTS = Path(__file__).parent / "results"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=1_000_000)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--tier", default="cpu")
    p.add_argument("--out", type=Path, default=RESULTS)
    a = p.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, as the goal states
    seeds = np.arange(a.seeds)
    result = {"tier": a.tier, "device": tier_name(), "versions": versions(), "date": time.strftime("%Y-%m-%d"),
              "n_seeds": a.seeds, "cores": 1, "resets": {}}
    for reset in ("chapter", "task"):
        times = []
        for _ in range(a.repeats):
            t0 = time.perf_counter()
            start_poses(seeds, reset=reset)
            times.append(time.perf_counter() - t0)
        # the per-seed reference on a sample, scaled: what one default_rng per seed costs
        sample = seeds[:20_000]
        t0 = time.perf_counter()
        [start_state(int(s), reset) for s in sample]
        per_seed = (time.perf_counter() - t0) / len(sample)
        result["resets"][reset] = {"seconds_median": round(statistics.median(times), 4),
                                   "seconds_all": [round(t, 4) for t in times],
                                   "one_generator_per_seed_seconds_estimated": round(per_seed * a.seeds, 2)}
        print(f"{reset}: {a.seeds:,} start poses in {statistics.median(times):.3f} s (median of {a.repeats}); "
              f"one default_rng per seed: ~{per_seed * a.seeds:.1f} s", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / f"{a.tier}-start-poses.json"
    path.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
