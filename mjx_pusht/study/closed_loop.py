"""Closed-loop comparison: the same controller's episodes on MJX and on MuJoCo C, seed by seed."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from mjx_pusht.backends.base import versions
from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.backends.mjx import MjxBackend
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.outcomes import final_diff
from mjx_pusht.study.report import render_episodes_markdown
from mjx_pusht.study.stats import distribution, summarize_episodes


def paired_diff(a: np.ndarray, b: np.ndarray, z: float = 1.959964) -> dict:
    """Difference of two success rates on the same seeds, with a 95% interval from the paired
    (discordant-pair) variance: mjx - cpu."""
    n = len(a)
    only_a, only_b = int((a & ~b).sum()), int((~a & b).sum())
    diff = (only_a - only_b) / n
    se = np.sqrt(max(only_a + only_b - (only_a - only_b) ** 2 / n, 0.0)) / n
    return {"difference": diff, "ci95": [diff - z * se, diff + z * se], "only_mjx": only_a, "only_cpu": only_b}


def compare_episodes(seeds: np.ndarray, impl: str, out: Path, *, controller=None, reset: str | None = None,
                     episode=None, progress=print, workers: int = 1, task: str = "chapter") -> dict:
    """The controller (default: the task's expert) on the same seeds on the CPU reference and on MJX (`impl`:
    jax or warp) or, for the gym-pusht task, gym-pusht itself (`impl` "gym-pusht"): success rates with
    intervals, per-seed agreement, and final-pose differences against the CPU's own sensitivity (the same CPU
    run from float32-rounded starts, the rounding MJX starts from)."""
    from mjx_pusht.backends.factory import make_backend
    from mjx_pusht.task.controllers import describe
    from mjx_pusht.task.reset import start_poses
    from mjx_pusht.task.tasks import get as get_task

    the_task = get_task(task)
    reset = the_task.check_reset(reset)
    controller = controller or the_task.controller("expert")
    episode = episode or the_task.episode()
    seeds = np.asarray(seeds, np.int64)
    t0 = time.perf_counter()
    name = impl if impl == "gym-pusht" else f"mjx-{impl}"
    starts = f"{task}'s starts" if reset == task else f"{task}'s {reset} starts"  # not "gym-pusht's gym-pusht starts"
    progress(f"[compare] {describe(controller)} on {starts}: {name} ...")
    scenario = Scenario(the_task.scene(), reset=reset, controller=controller, episode=episode)
    backend = make_backend(name, scenario) if impl == "gym-pusht" else MjxBackend(scenario, impl)
    try:
        # (gym-pusht checks that its own seeded starts are the ones task/reset.py draws)
        mjx_r = backend.run(seeds, batch=len(seeds), poses=start_poses(seeds, reset=reset) if impl == "gym-pusht" else None)
    finally:
        backend.close()
    scene = backend.simulated_scene
    sc = Scenario(scene, reset=reset, controller=controller, episode=episode)
    from mjx_pusht.backends.cpu import FeedbackPool

    pool = FeedbackPool(workers) if workers > 1 else None
    cpu = pool.run if pool is not None else run_cpu
    try:
        progress("[compare] CPU reference ...")
        cpu_r = cpu(sc, seeds)
        progress("[compare] CPU from float32-rounded starts (the CPU's own sensitivity) ...")
        jit = cpu(sc, seeds, poses=start_poses(seeds, reset=reset).astype(np.float32).astype(np.float64))
    finally:
        if pool is not None:
            pool.close()
    report = episodes_report(mjx_r, cpu_r, jit, impl=name, device=backend.device, pusher_shape=backend.pusher,
                             controller=describe(controller), task=task, reset=reset,
                             episode={"frame_skip": episode.frame_skip, "max_steps": episode.max_steps,
                                      "success": episode.success}, versions=versions())
    report["wall_seconds"] = round(time.perf_counter() - t0, 1)
    return write_report(out, report)


def episodes_report(mjx_r, cpu_r, jit=None, **meta) -> dict:
    """The closed-loop report of the same episodes on MJX (`mjx_r`) and on MuJoCo C (`cpu_r`), row by row;
    `jit`, the CPU from float32-rounded starts, is the yardstick for how far apart chaos alone puts them
    (None where it was not run: the row-by-row figures against it are then left out)."""
    ok_m, ok_c = (np.asarray(r.episode["success"], bool) for r in (mjx_r, cpu_r))
    steps = lambda r: np.asarray(r.episode["steps_to_success"])  # noqa: E731
    report = {"kind": "closed loop", **meta, "n_seeds": int(len(cpu_r)),
              "cpu": summarize_episodes(cpu_r), "mjx": summarize_episodes(mjx_r),
              "success_difference_mjx_minus_cpu": paired_diff(ok_m, ok_c),
              "per_seed_success_agreement": {"mjx_vs_cpu": float((ok_m == ok_c).mean())},
              "steps_to_success_abs_diff_where_both_succeed": {
                  "mjx_vs_cpu": distribution(np.abs(steps(mjx_r) - steps(cpu_r))[ok_m & ok_c])},
              "final_pose_diff": {"mjx_vs_cpu": final_diff(mjx_r, cpu_r)},
              "rigid": {"cpu": float(cpu_r.rigid.mean()), "mjx": float(mjx_r.rigid.mean())},
              "cpu_f32_starts": None, "success_difference_cpu_f32_minus_cpu": None}
    if jit is not None:
        ok_j = np.asarray(jit.episode["success"], bool)
        report["cpu_f32_starts"] = summarize_episodes(jit)
        report["success_difference_cpu_f32_minus_cpu"] = paired_diff(ok_j, ok_c)
        report["per_seed_success_agreement"]["cpu_f32_vs_cpu"] = float((ok_j == ok_c).mean())
        report["steps_to_success_abs_diff_where_both_succeed"]["cpu_f32_vs_cpu"] = distribution(
            np.abs(steps(jit) - steps(cpu_r))[ok_j & ok_c])
        report["final_pose_diff"]["cpu_f32_vs_cpu"] = final_diff(jit, cpu_r)
    return report


# What two eval runs must share to be paired row by row: everything that makes an episode but the backend (the task
# first: two tasks differ in their actions too, and the task is the difference to name).
_SAME = ("task", "controller_sha256", "action", "reset", "break_it", "max_steps", "frame_skip", "params")
# What the pairing reads from each eval's summary.json (and its config block)
_NEEDS = ("backend", "controller")
_NEEDS_CONFIG = ("backend", "controller", "reset", "max_steps", "frame_skip")


def evals_report(first: Path, second: Path) -> dict:
    """The closed-loop report (`write_report` writes it) from two finished `eval` folders, one on MuJoCo C and
    one on MJX, of the same controller on the same seeds: for runs that could not share a machine (a pixel
    policy's CPU side renders through EGL; the GPU that ran MJX-Warp may have none). Anything that would pair
    unlike episodes (other seeds, another controller file, other episode settings, two CPU runs) is refused, not
    reported. It reads and checks both before anything is written, so `compare --evals` claims its --out only
    for a pairing it can report."""
    from mjx_pusht.backends.results import Rollouts
    from mjx_pusht.errors import ConfigError
    from mjx_pusht.io.outputs import read_table

    runs = []
    for folder in (Path(first), Path(second)):
        summary, table = folder / "summary.json", folder / "per_episode.parquet"
        if not summary.is_file() or not table.is_file():
            raise ConfigError(f"{folder} is not a finished eval folder (it needs summary.json and per_episode.parquet)")
        try:
            s = json.loads(summary.read_text())
            command = s["config"]["command"]
        except (ValueError, KeyError, TypeError) as e:
            raise ConfigError(f"{summary} is not an mjx-pusht summary ({type(e).__name__}: {e})") from None
        if command != "eval":
            raise ConfigError(f"{folder} holds a {command} run, not an eval")
        missing = [k for k in _NEEDS if not isinstance(s.get(k), str)] + \
            [f"config.{k}" for k in _NEEDS_CONFIG if k not in s["config"]]
        if missing:  # an eval's summary cut or edited by hand: the pairing would read these
            raise ConfigError(f"{summary} lacks {', '.join(missing)}: not a finished eval's summary")
        try:  # a cut or foreign table (pyarrow's errors are ValueErrors; a missing column a KeyError)
            rows = Rollouts.from_columns(read_table(table))
        except (ValueError, KeyError, OSError) as e:
            raise ConfigError(f"{table} is not an eval's table ({type(e).__name__}: {str(e).splitlines()[0]})") from None
        runs.append((folder, s, rows))
    if sorted(s["config"]["backend"] == "cpu" for _, s, _ in runs) != [False, True]:
        raise ConfigError("--evals pairs one eval on the cpu backend with one on MJX or gym-pusht: these ran on "
                          f"{runs[0][1]['config']['backend']} and {runs[1][1]['config']['backend']}")
    (cpu_dir, s_cpu, cpu_r), (mjx_dir, s_mjx, mjx_r) = sorted(runs, key=lambda r: r[1]["config"]["backend"] != "cpu")
    c_cpu, c = s_cpu["config"], s_mjx["config"]
    # a policy is the same policy by its file's hash where both runs recorded one (evals since change 27), by
    # its controller string where either did not
    by_hash = c_cpu.get("controller_sha256") and c.get("controller_sha256")
    same = _SAME if by_hash else tuple("controller" if k == "controller_sha256" else k for k in _SAME)
    for key in same:
        if c_cpu.get(key) != c.get(key):
            raise ConfigError(f"the two evals differ in {key} ({c_cpu.get(key)!r} on the cpu, {c.get(key)!r} on "
                              f"{c['backend']}): their episodes are not the same episodes")
    if s_cpu.get("success_coverage") != s_mjx.get("success_coverage"):  # every eval's summary has it
        raise ConfigError(f"the two evals judged success at other coverages ({s_cpu.get('success_coverage')} on the "
                          f"cpu, {s_mjx.get('success_coverage')} on {c['backend']}): their verdicts do not pair")
    if len(cpu_r) != len(mjx_r) or not np.array_equal(np.unique(cpu_r.seeds), np.unique(mjx_r.seeds)) \
            or len(np.unique(cpu_r.seeds)) != len(cpu_r):
        only_cpu, only_mjx = np.setdiff1d(cpu_r.seeds, mjx_r.seeds), np.setdiff1d(mjx_r.seeds, cpu_r.seeds)
        raise ConfigError(f"the two evals ran other seeds ({len(only_cpu)} only on the cpu, {len(only_mjx)} only on "
                          f"MJX, of {len(cpu_r)} and {len(mjx_r)})")
    cpu_r, mjx_r = cpu_r.take(np.argsort(cpu_r.seeds)), mjx_r.take(np.argsort(mjx_r.seeds))
    report = episodes_report(mjx_r, cpu_r, None, impl=s_mjx["backend"], device=s_mjx.get("device"),
                             pusher_shape=s_mjx.get("pusher_shape"), controller=s_mjx["controller"], reset=c["reset"],
                             episode={"frame_skip": c["frame_skip"], "max_steps": c["max_steps"],
                                      "success": s_mjx.get("success_coverage")},
                             versions={"cpu": s_cpu.get("versions"), "mjx": s_mjx.get("versions")},
                             evals={"cpu": str(cpu_dir), "mjx": str(mjx_dir)}, cpu_device=s_cpu.get("device"),
                             controller_sha256={"cpu": c_cpu.get("controller_sha256"),
                                                "mjx": c.get("controller_sha256")})
    return report


def write_report(out: Path, report: dict) -> dict:
    """compare_episodes.json and .md in `out`: the closed-loop report, however its two sides were run."""
    from mjx_pusht.io.outputs import atomic_write_bytes, atomic_write_json

    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "compare_episodes.json", report)
    atomic_write_bytes(out / "compare_episodes.md", render_episodes_markdown(report).encode())
    return report
