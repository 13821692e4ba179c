"""Rerun determinism: the same seeds twice on one backend and device; are the rows byte-identical?

    python -m benchmarks.determinism --backend mjx-warp --seeds 4096 --out benchmarks/results/h100-determinism.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from mjx_pusht.backends.factory import make_backend
from mjx_pusht.io.banner import tier
from mjx_pusht.scenario import Scenario


def rerun_report(name: str, n: int, repeats: int = 3) -> dict:
    backend = make_backend(name, Scenario())
    return {"backend": name, "device": backend.device, "n_seeds": n, "repeats": repeats,
            "reruns": reruns(backend, n, repeats)}


def reruns(backend, n: int, repeats: int = 3) -> list[dict]:
    """Seeds 0..n-1 `repeats` times on one backend: per rerun, rows byte-identical to the first run."""
    seeds = np.arange(n)
    runs = [backend.run(seeds, batch=n) for _ in range(repeats)]
    ref = runs[0].columns()
    out = []
    for r in runs[1:]:
        cols = r.columns()
        same_row = np.ones(n, bool)
        worst = 0.0
        for k, v in ref.items():
            same_row &= cols[k] == v
            if v.dtype != bool:
                worst = max(worst, float(np.abs(cols[k] - v).max()))
        out.append({"identical_rows": int(same_row.sum()), "max_abs_diff": worst})
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--backends", default="mjx-jax,mjx-warp")
    p.add_argument("--seeds", type=int, default=4096)
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)
    res = {"tier": tier(), "results": [rerun_report(b, a.seeds) for b in a.backends.split(",")]}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(res, indent=2) + "\n")
    print(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
