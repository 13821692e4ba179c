"""CPU vs MJX: does the batch do the same physics as MuJoCo on the CPU, for this task?

Pushing a T by its stem is a bifurcation, so a per-seed final-pose diff is the
wrong criterion. This report checks what must agree exactly (structure, the
contact-free settle, the weld verdicts), measures when each seed's paths part,
and judges outcomes as distributions against a baseline of the CPU against
itself under an equally small change.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from mjx_pusht.backends.base import versions
from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.backends.mjx import MjxBackend
from mjx_pusht.backends.results import Rollouts
from mjx_pusht.model.scene import SceneSpec, build_model
from mjx_pusht.model.tree import read_tree
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.contacts import (
    contact_census,
    first_contact_steps,
    first_touch_contacts,
)
from mjx_pusht.study.outcomes import (
    DIVERGED_M,
    SPIN_RAD,
    divergence_steps,
    energy_distance,
    final_diff,
    outcome_modes,
    pose_vectors,
    tee_traj,
)
from mjx_pusht.study.report import plots, render_markdown
from mjx_pusht.study.stats import distribution


@dataclasses.dataclass
class Experiment:
    """One run to set against the CPU reference: a label, and how it was made."""

    label: str
    rollouts: Rollouts
    note: str


def _cpu_variant(scene: SceneSpec, seeds, *, jitter32: bool = False, **opt) -> Rollouts:
    """The CPU reference under a small change: start poses rounded to float32, or solver options."""
    from mjx_pusht.task.reset import start_poses

    model = build_model(scene)
    for k, v in opt.items():
        setattr(model.opt, k, v)
    poses = start_poses(seeds)
    if jitter32:
        poses = poses.astype(np.float32).astype(np.float64)
    return run_cpu(Scenario(scene), seeds, trace=True, model=model, poses=poses)


def compare(seeds: np.ndarray, impl: str, out: Path, *, root_cause: bool = True, progress=print,
            mjx_options: dict | None = None) -> dict:
    """Run the CPU reference and MJX (`impl`) on `seeds`, write compare.json, compare.md and plots.

    `mjx_options` (tolerance, iterations, ...) change MJX's solver only, so the report
    measures what such a setting costs in fidelity against the unchanged CPU reference.
    """
    mjx_options = dict(mjx_options or {})
    t0 = time.perf_counter()
    seeds = np.asarray(seeds, np.int64)
    report: dict = {"impl": f"mjx-{impl}", "n_seeds": int(len(seeds)), "versions": versions(),
                    "mjx_options": mjx_options}
    per_break = {}
    for break_it in ("none", "split-tee"):
        progress(f"[compare] {break_it}: MJX-{impl} ...")
        mjx_backend = MjxBackend(Scenario(SceneSpec(break_it)), impl, **mjx_options)
        mjx_r = mjx_backend.run(seeds, trace=True)
        scene = mjx_backend.simulated_scene  # what MJX simulated (capsule pusher on impl=jax)
        progress(f"[compare] {break_it}: CPU reference ...")
        cpu_r = run_cpu(Scenario(scene), seeds, trace=True)
        model = build_model(scene)
        tree = read_tree(model)
        a, b = tee_traj(model, mjx_r), tee_traj(model, cpu_r)
        settle = slice(0, Scenario().schedule.settle_steps + 1)
        contact = first_contact_steps(model, cpu_r.trace.qpos) if break_it == "none" else None
        entry = {
            "structure": {"tree": tree.to_dict(), "nq": tree.nq, "nv": tree.nv, "pusher_shape": scene.pusher,
                          "device": mjx_backend.device},
            "settle_max_abs_err": float(np.abs(a[:, settle] - b[:, settle]).max()),
            "verdict_agreement": float((mjx_r.rigid == cpu_r.rigid).mean()),
            "settled_gap_max_abs_diff": float(np.abs(mjx_r.gap_settled - cpu_r.gap_settled).max()),
            "rigid_fraction": {"cpu": float(cpu_r.rigid.mean()), "mjx": float(mjx_r.rigid.mean())},
            "non_finite": {"cpu": int((~cpu_r.finite).sum()), "mjx": int((~mjx_r.finite).sum())},
        }
        if contact is not None:
            pre = np.arange(a.shape[1])[None, :] < contact[:, None]
            entry["first_contact_step"] = distribution(contact)
            entry["pre_contact_max_abs_err"] = float(np.abs(a - b)[pre].max()) if pre.any() else 0.0
            entry["pre_contact_pusher_max_abs_err"] = float(
                np.abs(mjx_r.trace.qpos[..., -2:] - cpu_r.trace.qpos[..., -2:])[pre].max()) if pre.any() else 0.0
        entry["collision_functions"] = mjx_backend.collisions
        per_break[break_it] = (entry, mjx_r, cpu_r, model, mjx_backend)
        if break_it == "none":
            first_contacts = contact
        report[break_it] = entry

    entry, mjx_r, cpu_r, model, welded_backend = per_break["none"]
    scene = SceneSpec("none", per_break["none"][0]["structure"]["pusher_shape"])
    div = divergence_steps(tee_traj(model, mjx_r), tee_traj(model, cpu_r))
    contact = first_contacts
    report["divergence"] = {
        "threshold_m": DIVERGED_M,
        "step": distribution(div[div < mjx_r.trace.qpos.shape[1]]),
        "never_fraction": float((div >= mjx_r.trace.qpos.shape[1]).mean()),
        "steps_after_first_contact": distribution((div - contact)[div < mjx_r.trace.qpos.shape[1]]),
    }
    progress("[compare] CPU baselines (float32 start jitter, solver tolerance) ...")
    baselines = [
        Experiment("cpu_start_jitter_f32", _cpu_variant(scene, seeds, jitter32=True),
                   "CPU with start poses rounded to float32, the rounding MJX starts from"),
        Experiment("cpu_tolerance_1e-6", _cpu_variant(scene, seeds, tolerance=1e-6),
                   "CPU with solver tolerance 1e-6 instead of 1e-8"),
    ]
    ref = pose_vectors(cpu_r)
    e_mjx = energy_distance(pose_vectors(mjx_r), ref)
    e_base = {x.label: energy_distance(pose_vectors(x.rollouts), ref) for x in baselines}
    report["outcomes"] = {
        "energy_distance_m": {"mjx_vs_cpu": e_mjx, **{f"{k}_vs_cpu": v for k, v in e_base.items()}},
        "final_pose_diff": {"mjx_vs_cpu": final_diff(mjx_r, cpu_r),
                            **{f"{x.label}_vs_cpu": final_diff(x.rollouts, cpu_r) for x in baselines}},
        "outcome_within_cpu_baseline": bool(e_mjx <= max(e_base.values())),
        "baseline_notes": {x.label: x.note for x in baselines},
    }
    report["modes"] = {"definition": f"straight |yaw| < {SPIN_RAD} rad; spun beyond", "cpu": outcome_modes(cpu_r),
                       f"mjx-{impl}": outcome_modes(mjx_r), **{x.label: outcome_modes(x.rollouts) for x in baselines}}
    sensitive = np.linalg.norm(baselines[0].rollouts.final[:, :2] - cpu_r.final[:, :2], axis=1) > 1e-3
    off = np.linalg.norm(mjx_r.final[:, :2] - cpu_r.final[:, :2], axis=1) > 1e-3
    report["unexplained"] = {
        "note": "seeds where MJX ends >1 mm from CPU although the CPU itself is stable under float32 start jitter",
        "fraction": float((off & ~sensitive).mean()),
        "seeds": [int(s) for s in seeds[off & ~sensitive][:20]],
    }
    if impl == "warp":
        report["warp_parts"] = _warp_parts(seeds, welded_backend, mjx_r, cpu_r, ref, mjx_options, progress)
    if root_cause:
        report["root_cause"] = _root_cause(seeds, impl, scene, cpu_r, ref, progress)
    report["wall_seconds"] = round(time.perf_counter() - t0, 1)
    out.mkdir(parents=True, exist_ok=True)
    plots(out, mjx_r, cpu_r, div, impl)
    from mjx_pusht.io.outputs import atomic_write_bytes, atomic_write_json

    atomic_write_json(out / "compare.json", report)
    atomic_write_bytes(out / "compare.md", render_markdown(report).encode())
    return report


def _warp_parts(seeds, backend, mjx_r, cpu_r, ref, mjx_options, progress) -> dict:
    """How far MJX-Warp is from itself (a rerun: atomics reorder contacts) and what the collider choice
    costs (MuJoCo Warp's default GJK/EPA for box-box instead of the primitive MuJoCo C uses)."""
    progress("[compare] MJX-Warp again (run to run), and with MuJoCo Warp's default box-box collider ...")
    rerun = backend.run(seeds)
    other = not backend.runner.cfg.match_c_colliders
    alt = MjxBackend(Scenario(SceneSpec("none")), "warp", **{**mjx_options, "match_c_colliders": other}).run(seeds)
    label = "box_box_primitive" if other else "box_box_gjk_epa_default"
    progress("[compare] the pusher-tee contact at first touch: MuJoCo C and MJX-Warp on the CPU's own states ...")
    first = first_touch_contacts(backend, cpu_r, mjx_r)
    return {
        "first_touch_pusher_tee": first,
        "rerun_vs_first_run": final_diff(rerun, mjx_r),
        "rerun_vs_cpu": final_diff(rerun, cpu_r),
        f"{label}_vs_cpu": final_diff(alt, cpu_r),
        "energy_distance_m": {"rerun_vs_cpu": energy_distance(pose_vectors(rerun), ref),
                              f"{label}_vs_cpu": energy_distance(pose_vectors(alt), ref)},
        "this_report_box_box": "primitive box_box" if not other else "GJK/EPA",
    }


def _root_cause(seeds, impl, scene, cpu_r, ref, progress) -> dict:
    """Controlled runs, each changing one thing, set against the same CPU reference."""
    runs = {}
    progress("[compare] root cause: MJX, tighter solver ...")
    runs["mjx_iter200_ls100_tol1e-10"] = MjxBackend(Scenario(scene), impl, iterations=200, ls_iterations=100,
                                                   tolerance=1e-10).run(seeds)
    out = {}
    progress("[compare] root cause: contacts on the CPU's own states ...")
    out["contacts_on_cpu_states"] = contact_census(scene, impl, cpu_r, seeds)
    # last: x64 is process-wide in JAX, so it must not leak into the float32 runs above. MuJoCo Warp computes in
    # float32 only (its FFI refuses float64 arrays): its report says so rather than leaving the question out
    if impl != "warp":
        progress("[compare] root cause: MJX in float64 ...")
        runs["mjx_x64"] = MjxBackend(Scenario(scene), impl, x64=True).run(seeds)
    for label, r in runs.items():
        out[label] = {"final_pose_diff": final_diff(r, cpu_r), "energy_distance_m": energy_distance(pose_vectors(r), ref),
                      "modes": outcome_modes(r)}
    if impl == "warp":
        out["mjx_x64"] = "not run: MuJoCo Warp computes in float32 only (compare --backend mjx-jax runs it)"
    return out
