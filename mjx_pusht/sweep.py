"""Seed sweeps at scale: chunks written as they finish, resumable, summarised once at the end.

Chunk files live in DIR/.parts/ as seeds[lo:hi] of the sweep's seed list; the
table DIR/per_seed.parquet is assembled from them only when every seed is done,
so an interrupted sweep leaves finished chunks and never a corrupt table.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from mjx_pusht.outputs import atomic_write_json, atomic_write_table, read_table
from mjx_pusht.results import Rollouts

PARTS = ".parts"


class ResumeError(RuntimeError):
    """--resume asked for, but the folder's unfinished sweep is another sweep."""


@dataclasses.dataclass
class SweepRun:
    rollouts: Rollouts
    summary: dict
    compile_seconds: float
    run_seconds: float
    timing: dict = dataclasses.field(default_factory=dict)  # seconds per phase of run_sweep
    table: dict | None = None  # the chunk files' columns, concatenated: the table as written, scored once


def rows_for(seeds: np.ndarray, n_combos: int) -> tuple[np.ndarray, np.ndarray]:
    """The sweep's rows: every seed under every parameter combination, combination-major."""
    return np.tile(seeds, n_combos), np.repeat(np.arange(n_combos), len(seeds))


def _fingerprint(seeds: np.ndarray, config: dict) -> dict:
    return {"config": config, "n_seeds": int(len(seeds)), "seeds_sha256": hashlib.sha256(seeds.tobytes()).hexdigest()}


def _done_ranges(parts: Path) -> list[tuple[int, int]]:
    out = []
    for p in parts.glob("seeds-*.parquet"):
        lo, hi = p.stem.removeprefix("seeds-").split("-")
        out.append((int(lo), int(hi)))
    return sorted(out)


def check_resumable(out: Path, seeds: np.ndarray, config: dict, resume: bool) -> None:
    """Refuse to clobber an unfinished sweep, or to resume one that is not this sweep."""
    parts = out / PARTS
    manifest = parts / "manifest.json"
    if not manifest.exists():
        return
    done = _done_ranges(parts)
    if not resume:
        if done:
            raise ResumeError(
                f"{out} holds an unfinished sweep ({sum(h - lo for lo, h in done)} seeds done): "
                "pass --resume to finish it, or choose another --out"
            )
        return
    if json.loads(manifest.read_text()) != _fingerprint(seeds, config):
        raise ResumeError(f"--resume: the unfinished sweep in {out} used other seeds or settings; choose another --out")


def _is_out_of_memory(e: BaseException) -> bool:
    text = str(e).lower()
    return any(k in text for k in ("resource_exhausted", "out of memory", "failed to allocate", "oom"))


def run_sweep(
    backend,
    seeds: np.ndarray,
    out: Path,
    *,
    config: dict,
    chunk: int | None = None,
    resume: bool = False,
    progress: bool = True,
    combos: np.ndarray | None = None,
    episodes: bool = False,
) -> SweepRun:
    """Run every row (seed, or seed x parameter combination) in chunks, writing each chunk as it lands."""
    from tqdm import tqdm

    combos = np.zeros(len(seeds), np.int64) if combos is None else np.asarray(combos)
    parts = out / PARTS
    check_resumable(out, seeds, config, resume)
    if not resume and parts.exists():
        shutil.rmtree(parts)
    parts.mkdir(parents=True, exist_ok=True)
    atomic_write_json(parts / "manifest.json", _fingerprint(seeds, config))
    if not chunk and len(seeds):
        # the backend's default, but never a small sweep padded up to it (MJX: a multiple of its devices)
        n_dev = len(getattr(getattr(backend, "runner", None), "devices", None) or [None])
        chunk = min(backend.default_chunk, -(-len(seeds) // n_dev) * n_dev)
    chunk = int(chunk or backend.default_chunk)
    done = np.zeros(len(seeds), bool)
    for lo, hi in _done_ranges(parts):
        done[lo:hi] = True
    todo = np.flatnonzero(~done)
    from mjx_pusht.reset import start_poses

    scenario = getattr(backend, "scenario", None)
    reset = scenario.reset if scenario is not None else "chapter"
    t_poses = time.perf_counter()
    poses = np.zeros((len(seeds), 3 if reset == "chapter" else 5))
    poses[todo] = start_poses(seeds[todo], reset=reset)  # once for the whole sweep, vectorised over seeds
    timing = {"start_poses": time.perf_counter() - t_poses, "rollout_and_compile": 0.0, "scoring_and_chunk_writing": 0.0}
    t0 = time.perf_counter()
    compile0 = backend.compile_seconds
    bar = tqdm(total=len(seeds), initial=int(done.sum()), unit="seed", disable=not progress, file=sys.stderr,
               desc=f"sweep [{backend.name}]")
    i = 0
    while i < len(todo):
        lo = int(todo[i])
        hi = lo + 1  # a contiguous run of undone seeds, at most `chunk` long
        while hi < len(seeds) and hi - lo < chunk and not done[hi]:
            hi += 1
        t_run = time.perf_counter()
        try:
            rows = backend.run(seeds[lo:hi], batch=chunk, combos=combos[lo:hi], poses=poses[lo:hi])
        except Exception as e:  # noqa: BLE001 - only memory errors are retried
            if not _is_out_of_memory(e) or chunk <= 1:
                raise
            chunk //= 2
            bar.write(f"out of memory at chunk {chunk * 2}; retrying with --chunk {chunk}")
            continue
        t_write = time.perf_counter()
        timing["rollout_and_compile"] += t_write - t_run
        atomic_write_table(parts / f"seeds-{lo:012d}-{hi:012d}.parquet", rows.columns(episodes=episodes))
        timing["scoring_and_chunk_writing"] += time.perf_counter() - t_write
        done[lo:hi] = True
        i += hi - lo
        bar.update(hi - lo)
    bar.close()
    wall = time.perf_counter() - t0
    compile_s = backend.compile_seconds - compile0
    tables = [read_table(parts / f"seeds-{lo:012d}-{hi:012d}.parquet") for lo, hi in _done_ranges(parts)]
    table = {k: np.concatenate([t[k] for t in tables]) for k in tables[0]} if tables else {}
    rollouts = Rollouts.from_columns(table) if tables else Rollouts.empty()
    if not np.array_equal(rollouts.seeds, seeds) or len(rollouts) != len(seeds):
        raise RuntimeError(f"chunk files in {parts} do not cover the sweep's seeds; remove the folder and rerun")
    timing["compile"] = compile_s
    timing["rollout"] = max(timing["rollout_and_compile"] - compile_s, 0.0)
    return SweepRun(rollouts, {}, compile_s, max(wall - compile_s, 1e-9), timing, table)


def finish(out: Path, run: SweepRun, *, name: str = "per_seed.parquet", episodes: bool = False) -> None:
    """Write the table, then drop the chunk files (the table now holds them). The chunks were scored
    as they were written, so the table is their columns, not a second scoring of every row."""
    atomic_write_table(out / name, run.table if run.table else run.rollouts.columns(episodes=episodes))
    shutil.rmtree(out / PARTS, ignore_errors=True)


def _stats(x: np.ndarray) -> dict:
    if x.size == 0:
        return {"n": 0}
    return {
        "n": int(x.size),
        "min": float(x.min()),
        "median": float(np.median(x)),
        "mean": float(x.mean()),
        "p99": float(np.quantile(x, 0.99)),
        "max": float(x.max()),
    }


def _task_summary(rollouts: Rollouts) -> dict:
    """The PushT score over finite seeds: success rate at coverage >= 0.95, and the error spreads."""
    from mjx_pusht.score import SUCCESS_COVERAGE, task_score

    s = task_score(rollouts.final[rollouts.finite]) if rollouts.finite.any() else None
    if s is None:
        return {"n": 0}
    return {
        "success_coverage": SUCCESS_COVERAGE,
        "success_rate": float(s["success"].mean()),
        "coverage": _stats(s["coverage"]),
        "pos_err": _stats(s["pos_err"]),
        "abs_yaw_err": _stats(np.abs(s["yaw_err"])),
    }


def summarize(rollouts: Rollouts, *, backend, schedule, break_it: str, compile_s: float, run_s: float) -> dict:
    """summary.json: what ran where, the verdicts, and the speed. Non-finite seeds are counted, never averaged in."""
    from mjx_pusht.backends import versions

    finite = rollouts.finite
    n = len(rollouts)
    return {
        "backend": backend.name,
        "device": backend.device,
        "versions": versions(),
        "pusher_shape": backend.pusher,
        "warp_buffers": getattr(backend, "buffer_info", None),
        "warp_kernels": getattr(backend, "warp_kernels", None),
        "collision_functions": getattr(backend, "collisions", None),
        "n_seeds": n,
        "steps": schedule.nudge_steps,
        "settle_steps": schedule.settle_steps,
        "total_steps": schedule.total_steps,
        "break_it": break_it,
        "rigid_fraction": float(rollouts.rigid.mean()) if n else 0.0,
        "n_rigid": int(rollouts.rigid.sum()),
        "n_non_finite": int((~finite).sum()),
        "non_finite_seeds": [int(s) for s in rollouts.seeds[~finite][:100]],
        "n_escaped": int((~rollouts.contained).sum()),
        "escaped_seeds": [int(s) for s in rollouts.seeds[~rollouts.contained][:100]],
        "gap_max_dev": _stats(rollouts.gap_max_dev[finite]),
        "tee_gap_settled": _stats(rollouts.gap_settled[finite]),
        "tee_final_y": _stats(rollouts.final[finite, 1]),
        "task": _task_summary(rollouts),
        "compile_seconds": round(compile_s, 3),
        "run_seconds": round(run_s, 3),
        "steps_per_second": round(n * schedule.total_steps / run_s, 1) if run_s > 0 else None,
    }
