"""Seed sweeps at scale: chunks written as they finish, resumable, summarised once at the end.

Chunk files live in DIR/.parts/ as seeds[lo:hi] of the sweep's seed list; the
table DIR/per_seed.parquet is assembled from them only when every seed is done,
so an interrupted sweep leaves finished chunks and never a corrupt table.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from mjx_pusht.backends.actions import NonFiniteActionError
from mjx_pusht.backends.results import Rollouts
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.io.outputs import atomic_write_json, atomic_write_table, read_table, remove_own
from mjx_pusht.study.stats import distribution, warning_summary

PARTS = ".parts"


class ResumeError(MjxPushtError, RuntimeError):
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


def fingerprint(seeds: np.ndarray, config: dict) -> dict:
    return {"config": config, "n_seeds": int(len(seeds)), "seeds_sha256": hashlib.sha256(seeds.tobytes()).hexdigest()}


def kept_chunks(out) -> str:
    """What an interrupted sweep or eval leaves in `out`, and how to go on: its finished chunks, or none yet."""
    done = _done_ranges(Path(out) / PARTS)
    table = next((n for n in ("per_seed.parquet", "per_episode.parquet") if (Path(out) / n).is_file()), None)
    if not done and table:  # interrupted after its chunks were joined: what follows the table may be missing
        return f"the table {out}/{table} is whole; what is written after it may not be: rerun the same command"
    if not done:  # --resume would find nothing to finish
        return f"no chunk was finished yet in {out}: rerun without --resume to start"
    return (f"the finished chunks ({sum(hi - lo for lo, hi in done):,} rows) are kept in {out}/{PARTS}: rerun with "
            "--resume to finish")


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
    what = config.get("command", "sweep")  # an eval's chunks are an eval's (it said "sweep": the fourteenth pass)
    if not resume:
        if done:
            raise ResumeError(
                f"{out} holds an unfinished {what} ({sum(h - lo for lo, h in done)} seeds done): "
                "pass --resume to finish it, or choose another --out"
            )
        return
    try:
        theirs = json.loads(manifest.read_text())
    except (OSError, ValueError) as e:
        raise ResumeError(f"--resume: {manifest} is unreadable ({type(e).__name__}), so its chunks cannot be trusted; "
                          f"choose another --out (or remove {parts} to run every seed again)") from None
    if theirs != fingerprint(seeds, config):
        raise ResumeError(f"--resume: the unfinished {what} in {out} used other seeds or settings; choose another --out")
    for (_, hi), (lo, _) in zip(done, done[1:]):  # chunks of runs split otherwise (the fifteenth pass): at the end,
        if lo < hi:  # after every row had run, the table failed in a traceback and the other process waited for ever
            raise ResumeError(f"--resume: chunk files in {parts} overlap (rows {lo}..{hi - 1} twice), so they are not "
                              f"one run's; remove {parts} to run every seed again")
    import pyarrow.parquet as pq

    for lo, hi in done:  # before any work: a chunk cut or damaged on disk would only show at the end
        chunk = parts / f"seeds-{lo:012d}-{hi:012d}.parquet"
        try:
            rows = pq.read_metadata(chunk).num_rows
        except (OSError, ValueError) as e:
            raise ResumeError(f"--resume: chunk file {chunk} is unreadable ({str(e).splitlines()[0]}); remove it "
                              "and rerun with --resume to run its seeds again") from None
        if rows != hi - lo:
            raise ResumeError(f"--resume: chunk file {chunk} holds {rows} rows, not {hi - lo}; remove it and rerun "
                              "with --resume to run its seeds again")


def _is_out_of_memory(e: BaseException) -> bool:
    """A device's memory error (retried at half the chunk); never a user's controller's own error, and "oom" only
    as a word (a controller's "boom" was retried seven times as out of memory: the tenth hostile pass)."""
    import re

    from mjx_pusht.task.controller_base import ControllerError

    text = str(e).lower()
    return not isinstance(e, ControllerError) and (
        any(k in text for k in ("resource_exhausted", "out of memory", "failed to allocate")) or
        re.search(r"\boom\b", text) is not None)


def _stop_at_failed_write(written: list, parts: Path) -> None:
    """Raise, in one line, at the first chunk file that failed to land (a full disk, a folder gone):
    the chunks before it stay in `parts`, and --resume picks up from them."""
    from mjx_pusht.io.outputs import OutputError

    for f in written:
        if f.done() and f.exception() is not None:
            e = f.exception()
            if not isinstance(e, OSError):
                raise e  # not the disk: a bug, with its traceback
            kept = len(list(parts.glob("seeds-*.parquet")))
            raise OutputError(f"writing a chunk to {parts} failed ({e.strerror or e}); stopped there with {kept} chunk "
                              f"files kept: make room and rerun with --resume") from None


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
    on_start=None,
    processes=None,
) -> SweepRun:
    """Run every row (seed, or seed x parameter combination) in chunks, writing each chunk as it lands."""
    from tqdm import tqdm

    from mjx_pusht.study.distributed import Processes

    processes = processes or Processes()
    combos = np.zeros(len(seeds), np.int64) if combos is None else np.asarray(combos)
    parts = out / PARTS
    if processes.leader:  # one process clears and stamps the folder; the rest wait for it
        check_resumable(out, seeds, config, resume)
        if not resume:
            remove_own(parts)
        parts.mkdir(parents=True, exist_ok=True)
        atomic_write_json(parts / "manifest.json", fingerprint(seeds, config))
    processes.barrier("parts-ready")
    first, last = processes.block(len(seeds))  # this process's rows; all of them for one process
    if not chunk and len(seeds):
        # the backend's default, but never a small sweep padded up to it (MJX: a multiple of its devices)
        n_dev = len(backend.devices)
        chunk = min(backend.default_chunk, -(-len(seeds) // n_dev) * n_dev)
    chunk = int(chunk or backend.default_chunk)
    done = np.ones(len(seeds), bool)
    done[first:last] = False  # rows outside the block are other processes' work
    for lo, hi in _done_ranges(parts):
        done[lo:hi] = True
    todo = np.flatnonzero(~done)
    from mjx_pusht.task.reset import start_poses

    reset = backend.scenario.reset
    t_poses = time.perf_counter()
    poses = np.zeros((len(seeds), 3 if reset == "chapter" else 5))
    poses[todo] = start_poses(seeds[todo], reset=reset)  # once for the whole sweep, vectorised over seeds
    timing = {"start_poses": time.perf_counter() - t_poses, "rollout_and_compile": 0.0, "scoring_and_chunk_writing": 0.0}
    if on_start is not None:
        on_start(poses)  # e.g. the audit's CPU rows, run beside the device's
    t0 = time.perf_counter()
    compile0 = backend.compile_seconds
    bar = tqdm(total=last - first, initial=int(done[first:last].sum()), unit="seed", disable=not progress,
               file=sys.stderr, desc=f"{'eval' if episodes else 'sweep'} [{backend.name}]"
               + (f" process {processes.process_id}" if processes.many else ""))
    # Pipelined where the backend can: chunk k + 1 is on the device while the host scores chunk k
    # and a writer thread puts its file on disk. The chunks still land one file each, in order.
    pipelined = backend.pipelined
    writer = ThreadPoolExecutor(max_workers=1, thread_name_prefix="chunk-writer")
    written, tables = [], {}
    pending: list = []  # (lo, hi, submitted) in launch order, at most two

    def next_range(start: int):
        lo = start
        while lo < len(seeds) and done[lo]:
            lo += 1
        hi = lo + 1  # a contiguous run of undone seeds, at most `chunk` long
        while hi < len(seeds) and hi - lo < chunk and not done[hi]:
            hi += 1
        return (lo, min(hi, len(seeds))) if lo < len(seeds) else None

    def launch(lo, hi):
        return backend.submit(seeds[lo:hi], batch=chunk, combos=combos[lo:hi], poses=poses[lo:hi])

    def land(lo, hi, submitted):
        t_run = time.perf_counter()
        rows = backend.collect(submitted)
        t_score = time.perf_counter()
        timing["rollout_and_compile"] += t_score - t_run
        cols = rows.columns(episodes=episodes)
        tables[lo] = cols
        if written:  # the previous chunk's file has had this chunk's rollout to land: at most one write in flight,
            written[-1].exception()  # so a chunk that could not be written stops the run at the next, not at 100%
        _stop_at_failed_write(written, parts)
        written.append(writer.submit(atomic_write_table, parts / f"seeds-{lo:012d}-{hi:012d}.parquet", cols))
        timing["scoring_and_chunk_writing"] += time.perf_counter() - t_score
        done[lo:hi] = True
        bar.update(hi - lo)

    cursor = 0
    try:
        while True:
            while len(pending) < (2 if pipelined else 1):
                r = next_range(cursor)
                if r is None:
                    break
                t_launch = time.perf_counter()
                pending.append((*r, launch(*r)))
                timing["rollout_and_compile"] += time.perf_counter() - t_launch
                cursor = r[1]
            if not pending:
                break
            lo, hi, submitted = pending[0]
            try:
                land(lo, hi, submitted)
            except NonFiniteActionError as e:  # the chunks before it stay, and --resume picks up from them
                for f in written:
                    f.exception()
                kept = len(list(parts.glob("seeds-*.parquet")))
                raise NonFiniteActionError(*e.args[:4], f"; {kept} finished chunk files are kept in {parts}: fix "
                                           "the controller and rerun with --resume" if kept else "; no chunk was "
                                           "finished: fix the controller and rerun") from None
            except Exception as e:  # noqa: BLE001 - only memory errors are retried
                if not _is_out_of_memory(e) or chunk <= 1:
                    raise
                for *_, other in pending[1:]:  # let what is in flight finish before the smaller retry
                    other.future.exception()
                pending.clear()
                cursor = lo
                chunk //= 2
                bar.write(f"out of memory at chunk {chunk * 2}; retrying with --chunk {chunk}")
                continue
            pending.pop(0)
        t_wait = time.perf_counter()
        for f in written:
            f.exception()  # wait for the last writes
        _stop_at_failed_write(written, parts)
        timing["scoring_and_chunk_writing"] += time.perf_counter() - t_wait
    finally:
        for *_, other in pending if pipelined else ():  # an error or ^C: nothing left running behind our back
            other.future.cancel()
        writer.shutdown(wait=True)
    bar.close()
    wall = time.perf_counter() - t0
    compile_s = backend.compile_seconds - compile0
    table, rollouts = assemble(parts, seeds[first:last], tables, first)
    timing["compile"] = compile_s
    timing["rollout"] = max(timing["rollout_and_compile"] - compile_s, 0.0)
    return SweepRun(rollouts, {}, compile_s, max(wall - compile_s, 1e-9), timing, table)


def assemble(parts: Path, seeds: np.ndarray, in_memory: dict | None = None, first: int = 0):
    """The table of rows [first, first + len(seeds)) from their chunk files (those just run, from memory),
    checked to cover exactly those seeds; and its Rollouts."""
    in_memory = in_memory or {}
    ranges = [(lo, hi) for lo, hi in _done_ranges(parts) if first <= lo and hi <= first + len(seeds)]
    cols = [in_memory[lo] if lo in in_memory else read_table(parts / f"seeds-{lo:012d}-{hi:012d}.parquet")
            for lo, hi in ranges]
    table = {k: np.concatenate([t[k] for t in cols]) for k in cols[0]} if cols else {}
    rollouts = Rollouts.from_columns(table) if cols else Rollouts.empty()
    if len(rollouts) != len(seeds) or not np.array_equal(rollouts.seeds, seeds):
        raise RuntimeError(f"chunk files in {parts} do not cover the sweep's seeds; remove the folder and rerun")
    return table, rollouts


def finish(out: Path, run: SweepRun, *, name: str = "per_seed.parquet", episodes: bool = False) -> None:
    """Write the table, then drop the chunk files (the table now holds them). The chunks were scored
    as they were written, so the table is their columns, not a second scoring of every row."""
    atomic_write_table(out / name, run.table if run.table else run.rollouts.columns(episodes=episodes))
    remove_own(out / PARTS)


def _task_summary(rollouts: Rollouts, table: dict | None = None) -> dict:
    """The PushT score over finite seeds: success rate at coverage >= 0.95, and the error spreads.
    A sweep's table already holds every row's score (its chunks were scored as they landed)."""
    from mjx_pusht.task.score import SUCCESS_COVERAGE, task_score

    if not rollouts.finite.any():
        return {"n": 0}
    if table and "task_coverage" in table:
        s = {k: np.asarray(table[f"task_{k}"])[rollouts.finite] for k in ("pos_err", "yaw_err", "coverage")}
    else:
        s = task_score(rollouts.final[rollouts.finite])
    return {
        "success_coverage": SUCCESS_COVERAGE,
        "success_rate": float((s["coverage"] >= SUCCESS_COVERAGE).mean()),
        "coverage": distribution(s["coverage"]),
        "pos_err": distribution(s["pos_err"]),
        "abs_yaw_err": distribution(np.abs(s["yaw_err"])),
    }


def nudge_run(schedule) -> str:
    """What a sweep runs, in words: the chapter's open-loop nudge, not a controller solving the task."""
    return (f"the chapter's nudge: {schedule.settle_steps} settle steps, then the pusher's velocity target held at "
            f"{tuple(schedule.nudge_ctrl)} m/s open-loop for {schedule.nudge_steps} steps; nothing steers the T to the goal, so the task's score is where the nudge "
            "left it (mjx-pusht eval scores controllers on the task)")


def summarize(rollouts: Rollouts, *, backend, schedule, break_it: str, compile_s: float, run_s: float,
              table: dict | None = None) -> dict:
    """summary.json: what ran where, the verdicts, and the speed. Non-finite seeds are counted, never averaged in."""
    from mjx_pusht.backends.base import versions

    finite = rollouts.finite
    n = len(rollouts)
    return {
        **backend.describe(),
        "versions": versions(),
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
        **warning_summary(rollouts),
        "gap_max_dev": distribution(rollouts.gap_max_dev[finite]),
        "tee_gap_settled": distribution(rollouts.gap_settled[finite]),
        "tee_final_y": distribution(rollouts.final[finite, 1]),
        # what was scored: read alone, a sweep's success rate near 0 (an open-loop nudge, no controller) looked like a
        # broken task
        "task": {"run": nudge_run(schedule), **_task_summary(rollouts, table)},
        "compile_seconds": round(compile_s, 3),
        "run_seconds": round(run_s, 3),
        "steps_per_second": round(n * schedule.total_steps / run_s, 1) if run_s > 0 else None,
    }
