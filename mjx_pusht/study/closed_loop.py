"""Closed-loop comparison: the same controller's episodes on MJX and on MuJoCo C, seed by seed."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from mjx_pusht.backends.base import versions
from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.backends.mjx import MjxBackend
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.outcomes import final_diff
from mjx_pusht.study.report import render_episodes_markdown
from mjx_pusht.study.stats import distribution


def paired_diff(a: np.ndarray, b: np.ndarray, z: float = 1.959964) -> dict:
    """Difference of two success rates on the same seeds, with a 95% interval from the paired
    (discordant-pair) variance: mjx - cpu."""
    n = len(a)
    only_a, only_b = int((a & ~b).sum()), int((~a & b).sum())
    diff = (only_a - only_b) / n
    se = np.sqrt(max(only_a + only_b - (only_a - only_b) ** 2 / n, 0.0)) / n
    return {"difference": diff, "ci95": [diff - z * se, diff + z * se], "only_mjx": only_a, "only_cpu": only_b}


def compare_episodes(seeds: np.ndarray, impl: str, out: Path, *, controller=None, reset: str = "task",
                     episode=None, progress=print, workers: int = 1) -> dict:
    """The controller (default: the expert) on the same seeds on the CPU reference and on MJX:
    success rates with intervals, per-seed agreement, and final-pose differences against the CPU's
    own sensitivity (the same CPU run from float32-rounded starts, the rounding MJX starts from)."""
    from mjx_pusht.study.stats import summarize_episodes
    from mjx_pusht.task.controllers import Expert, describe
    from mjx_pusht.task.episode import Episode
    from mjx_pusht.task.reset import start_poses

    controller = controller or Expert()
    episode = episode or Episode()
    seeds = np.asarray(seeds, np.int64)
    t0 = time.perf_counter()
    progress(f"[compare] {describe(controller)} on {reset} starts: MJX-{impl} ...")
    backend = MjxBackend(Scenario(reset=reset, controller=controller, episode=episode), impl)
    mjx_r = backend.run(seeds, batch=len(seeds))
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
    ok_m, ok_c, ok_j = (np.asarray(r.episode["success"], bool) for r in (mjx_r, cpu_r, jit))
    steps = lambda r: np.asarray(r.episode["steps_to_success"])  # noqa: E731
    both = ok_m & ok_c
    report = {
        "kind": "closed loop", "impl": f"mjx-{impl}", "device": backend.device, "pusher_shape": scene.pusher,
        "controller": describe(controller), "reset": reset, "n_seeds": int(len(seeds)),
        "episode": {"frame_skip": episode.frame_skip, "max_steps": episode.max_steps, "success": episode.success},
        "versions": versions(),
        "cpu": summarize_episodes(cpu_r), "mjx": summarize_episodes(mjx_r), "cpu_f32_starts": summarize_episodes(jit),
        "success_difference_mjx_minus_cpu": paired_diff(ok_m, ok_c),
        "success_difference_cpu_f32_minus_cpu": paired_diff(ok_j, ok_c),
        "per_seed_success_agreement": {"mjx_vs_cpu": float((ok_m == ok_c).mean()),
                                       "cpu_f32_vs_cpu": float((ok_j == ok_c).mean())},
        "steps_to_success_abs_diff_where_both_succeed": {
            "mjx_vs_cpu": distribution(np.abs(steps(mjx_r) - steps(cpu_r))[both]),
            "cpu_f32_vs_cpu": distribution(np.abs(steps(jit) - steps(cpu_r))[ok_j & ok_c])},
        "final_pose_diff": {"mjx_vs_cpu": final_diff(mjx_r, cpu_r), "cpu_f32_vs_cpu": final_diff(jit, cpu_r)},
        "rigid": {"cpu": float(cpu_r.rigid.mean()), "mjx": float(mjx_r.rigid.mean())},
    }
    report["wall_seconds"] = round(time.perf_counter() - t0, 1)
    from mjx_pusht.io.outputs import atomic_write_bytes, atomic_write_json

    out.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out / "compare_episodes.json", report)
    atomic_write_bytes(out / "compare_episodes.md", render_episodes_markdown(report).encode())
    return report
