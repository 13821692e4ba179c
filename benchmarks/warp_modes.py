"""MJX-Warp's first call, its modes and its per-step overhead, each measured in a fresh process.

Variants (each a subprocess, since Warp's determinism and XLA's flags are process-wide):
- `cold-lazy` / `cold`: first call (runner built, 4096 seeds rolled out) on empty Warp and JAX
  caches, kernels compiled lazily one by one / found and compiled on all cores up front;
  `warm`: the same again in a second process, from the caches `cold` filled;
- `rate`: steps/s at --batch (median of repeats) and rerun determinism (rows identical over 3
  runs of 4096 seeds), for MJX's default graph mode, for graph_mode=JAX (XLA captures the
  FFI call), for JAX with XLA's WHILE command buffers, and for Warp's RUN_TO_RUN mode;
- `trace`: jax.profiler over one rollout at --batch: GPU time by kernel family and the idle
  share of the span, to see what the scan around MuJoCo Warp costs.

    python -m benchmarks.warp_modes --out benchmarks/results/h100-warp-modes.json
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COMMAND_BUFFERS = "--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL"


def _backend(cfg: dict):
    from mjx_pusht.backends.mjx import MjxBackend
    from mjx_pusht.scenario import Scenario

    cfg = dict(cfg)
    if cfg.pop("warp_deterministic", False):
        import warp as wp

        # before MuJoCo Warp creates its modules, so every kernel compiles with ordered atomics
        wp.config.deterministic = wp.DeterministicMode.RUN_TO_RUN
    return MjxBackend(Scenario(), "warp", **cfg)


def first_call(cfg: dict, seeds: int) -> dict:
    t0 = time.perf_counter()
    b = _backend(cfg)
    built = time.perf_counter() - t0
    out = b.run(np.arange(seeds))
    return {"first_call_seconds": round(time.perf_counter() - t0, 2), "runner_init_seconds": round(built, 2),
            "warp_kernels": b.warp_kernels, "rigid_fraction": float(out.rigid.mean())}


def rate(cfg: dict, batch: int, repeats: int, det_seeds: int) -> dict:
    from benchmarks.determinism import reruns
    from benchmarks.harness import measure

    b = _backend(cfg)
    row = measure(b, batch, repeats, b.scenario.schedule.total_steps)
    row.update(warp_kernels=b.warp_kernels, rerun_seeds=det_seeds,
               rerun_identical_rows=[r["identical_rows"] for r in reruns(b, det_seeds)])
    return row


def trace(cfg: dict, batch: int) -> dict:
    """GPU kernel time by family over one rollout, and how much of the span the GPU sat idle."""
    import jax
    from jax.profiler import ProfileData

    b = _backend(cfg)
    seeds = np.arange(batch)
    b.run(seeds)
    logdir = tempfile.mkdtemp()
    with jax.profiler.trace(logdir):
        t0 = time.perf_counter()
        b.run(seeds)
        wall = time.perf_counter() - t0
    pd = ProfileData.from_file(glob.glob(f"{logdir}/**/*.xplane.pb", recursive=True)[-1])
    by_name: dict[str, float] = {}
    intervals = []
    for plane in pd.planes:
        if not plane.name.startswith("/device:GPU"):
            continue
        for line in plane.lines:
            if not line.name.startswith("Stream"):
                continue
            for ev in line.events:
                by_name[ev.name] = by_name.get(ev.name, 0.0) + ev.duration_ns
                intervals.append((ev.start_ns, ev.start_ns + ev.duration_ns))
    if not intervals:
        return {"error": "no GPU stream events in the profile"}
    intervals.sort()
    busy, (cur_s, cur_e) = 0.0, intervals[0]
    for s, e in intervals[1:]:
        if s > cur_e:
            busy += cur_e - cur_s
            cur_s, cur_e = s, e
        else:
            cur_e = max(cur_e, e)
    busy += cur_e - cur_s
    span = intervals[-1][1] - intervals[0][0]

    def family(name: str) -> str:
        if "cuda_kernel_forward" in name or name.startswith("wp_"):
            return "warp"
        if "memcpy" in name.lower() or "memset" in name.lower():
            return "memcpy/memset"
        return "xla"

    fam: dict[str, float] = {}
    for k, v in by_name.items():
        fam[family(k)] = fam.get(family(k), 0.0) + v
    top = sorted(by_name.items(), key=lambda kv: -kv[1])[:25]
    return {"batch": batch, "wall_seconds": round(wall, 4), "gpu_span_ms": round(span / 1e6, 3),
            "gpu_busy_ms": round(busy / 1e6, 3), "idle_share_of_span": round(1 - busy / span, 4),
            "kernel_ms_by_family": {k: round(v / 1e6, 3) for k, v in fam.items()},
            "top_kernels_ms": [[k[:120], round(v / 1e6, 3)] for k, v in top], "events": len(intervals)}


def one(a) -> dict:
    cfg = json.loads(a.cfg)
    if a.kind == "first":
        return first_call(cfg, a.seeds)
    if a.kind == "rate":
        return rate(cfg, a.batch, a.repeats, a.seeds)
    return trace(cfg, a.batch)


VARIANTS = [
    # name, kind, cfg, cache tag (fresh caches per tag), extra XLA flags
    ("cold-lazy", "first", {"precompile": False}, "lazy", ""),
    ("cold", "first", {}, "main", ""),
    ("warm", "first", {}, "main", ""),
    ("rate-default", "rate", {}, "main", ""),
    ("rate-graph-jax", "rate", {"graph_mode": "JAX"}, "main", ""),
    ("rate-graph-jax-while-command-buffer", "rate", {"graph_mode": "JAX"}, "main", COMMAND_BUFFERS),
    ("trace-default", "trace", {}, "main", ""),
    ("cold-deterministic", "first", {"warp_deterministic": True}, "det", ""),
    ("rate-deterministic", "rate", {"warp_deterministic": True}, "det", ""),
]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", type=Path)
    p.add_argument("--batch", type=int, default=65536)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--seeds", type=int, default=4096)
    p.add_argument("--only", default=None, help="comma list of variant names")
    p.add_argument("--cache-root", type=Path, default=None, help="where the fresh caches go (default: a temp dir)")
    p.add_argument("--log-dir", type=Path, default=None, help="one log per variant (default: the cache root)")
    p.add_argument("--timeout", type=float, default=300, help="seconds a variant may take before it is stopped")
    p.add_argument("--one", dest="kind", default=None, help=argparse.SUPPRESS)
    p.add_argument("--cfg", default="{}", help=argparse.SUPPRESS)
    p.add_argument("--result", type=Path, default=None, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.kind:
        a.result.write_text(json.dumps(one(a)))
        return 0

    from mjx_pusht.backends.base import versions
    from mjx_pusht.io.banner import tier

    root = a.cache_root or Path(tempfile.mkdtemp(prefix="warp-modes-"))
    out: dict = {"tier": tier(), "versions": versions(), "batch": a.batch, "variants": {}}
    only = set(a.only.split(",")) if a.only else None
    unknown = (only or set()) - {v[0] for v in VARIANTS}
    if unknown:
        p.error(f"unknown variant(s) {', '.join(sorted(unknown))}; choose from {', '.join(v[0] for v in VARIANTS)}")
    for name, kind, cfg, tag, xla in VARIANTS:
        if only and name not in only:
            continue
        env = dict(os.environ, WARP_CACHE_PATH=str(root / f"warp-{tag}"), MJX_PUSHT_JAX_CACHE=str(root / f"jax-{tag}"))
        if xla:
            env["XLA_FLAGS"] = (env.get("XLA_FLAGS", "") + " " + xla).strip()
        res = root / f"{name}.json"
        t0 = time.perf_counter()
        log = (a.log_dir or root) / f"{name}.log"  # Warp's per-module load times, written as they come
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, "w") as f:
            try:
                rc = subprocess.run([sys.executable, "-m", "benchmarks.warp_modes", "--one", kind, "--cfg",
                                     json.dumps(cfg), "--batch", str(a.batch), "--repeats", str(a.repeats),
                                     "--seeds", str(a.seeds), "--result", str(res)],
                                    env=env, stdout=f, stderr=subprocess.STDOUT, timeout=a.timeout).returncode
            except subprocess.TimeoutExpired:
                rc = f"timed out after {a.timeout} s"
        row = json.loads(res.read_text()) if rc == 0 and res.exists() else {
            "error": f"exit {rc}", "log_tail": log.read_text()[-2000:]}
        row.update(process_seconds=round(time.perf_counter() - t0, 1), cfg=cfg, xla_flags=xla)
        out["variants"][name] = row
        print(name, json.dumps(row)[:600], flush=True)
        if a.out:
            a.out.parent.mkdir(parents=True, exist_ok=True)
            a.out.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
