"""Where MJX-Warp's time goes on this scene, and why its reruns differ.

Runs MuJoCo Warp directly (the engine inside MJX's warp impl) on the welded scene
with the sweep's start poses and schedule, and writes one JSON with:
- `event_trace`: GPU time per pipeline stage (MuJoCo Warp's own event timers), summed
  over the 160 steps, without graph capture so every stage is timed;
- `solver`: per step, the mean / p99 / max solver iterations over worlds and the share
  of worlds that hit the iteration limit; the solver's loop runs until the slowest
  world is done, so the max is what the batch pays;
- `contacts`: contacts per world (mean / max) per step;
- `rates`: steps/s of the captured CUDA graph (MuJoCo Warp alone) and of MJX's
  jitted scan (this package's rollout) at the same batch, per solver setting;
- `determinism`: one collision pass run twice from one state: are the contact sets
  the same, and is their order in the buffer the same?

    python -m benchmarks.profile_warp --batch 65536 --out benchmarks/results/h100-profile.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def _flatten(trace: dict, prefix: str = "") -> dict[str, float]:
    """{'step/forward/...': total ms} from MuJoCo Warp's nested event trace."""
    out: dict[str, float] = {}
    for name, (events, sub) in trace.items():
        path = f"{prefix}/{name}" if prefix else name
        out[path] = out.get(path, 0.0) + float(sum(events))
        for k, v in _flatten(sub, path).items():
            out[k] = out.get(k, 0.0) + v
    return out


def _setup(batch: int, tolerance: float | None, iterations: int | None, buffers=(16, 48)):
    import mujoco
    import mujoco.mjx.third_party.mujoco_warp as mjw

    from mjx_pusht.backends.mjx import MjxConfig, mjx_model, simulated_scene
    from mjx_pusht.model.layout import QposLayout
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.reset import start_poses

    scenario = Scenario()
    # the model exactly as the package's MJX-Warp backend builds it
    mjm = mjx_model(simulated_scene(scenario, "warp"), MjxConfig(impl="warp", tolerance=tolerance, iterations=iterations))
    qpos0 = QposLayout.of(mjm).initial_qpos(mjm, start_poses(np.arange(batch))).astype(np.float32)
    m = mjw.put_model(mjm)
    d = mjw.put_data(mjm, mujoco.MjData(mjm), nworld=batch, nconmax=buffers[0], njmax=buffers[1])
    return scenario, mjm, m, d, qpos0


def _reset(d, qpos0):
    d.qpos.assign(qpos0)
    d.qvel.zero_()
    d.qacc_warmstart.zero_()
    d.time.zero_()


def profile(batch: int) -> dict:
    import mujoco.mjx.third_party.mujoco_warp as mjw
    import warp as wp
    from mujoco.mjx.third_party.mujoco_warp._src import warp_util

    scenario, mjm, m, d, qpos0 = _setup(batch, None, None)
    ctrl = scenario.schedule.controls().astype(np.float32)
    _reset(d, qpos0)
    mjw.step(m, d)  # compile every kernel before anything is timed
    wp.synchronize()
    _reset(d, qpos0)
    totals: dict[str, float] = {}
    niter, ncon, overflow = [], [], 0
    for u in ctrl:
        d.ctrl.assign(np.tile(u, (batch, 1)))
        with warp_util.EventTracer(enabled=wp.get_device().is_cuda) as tracer:
            mjw.step(m, d)
            wp.synchronize()
            for k, v in _flatten(tracer.trace()).items():
                totals[k] = totals.get(k, 0.0) + v
        it = d.solver_niter.numpy()
        niter.append([float(it.mean()), float(np.percentile(it, 99)), int(it.max()),
                      float((it >= mjm.opt.iterations).mean())])
        wid = d.contact.worldid.numpy()[: int(d.nacon.numpy()[0])]
        per_world = np.bincount(wid, minlength=batch)
        ncon.append([float(per_world.mean()), int(per_world.max())])
        overflow |= int(np.bitwise_or.reduce(d.overflow.numpy()))
    niter_a, ncon_a = np.array(niter), np.array(ncon)
    step_ms = totals.get("step", sum(v for k, v in totals.items() if "/" not in k))
    return {
        "event_trace_ms_total_160_steps": {k: round(v, 3) for k, v in sorted(totals.items(), key=lambda kv: -kv[1])},
        "event_trace_share_of_step": {k: round(v / step_ms, 4) for k, v in totals.items() if k.count("/") <= 3},
        "solver": {
            "per_step_columns": ["mean_iterations", "p99_iterations", "max_iterations", "share_at_limit"],
            "per_step": niter_a.round(3).tolist(),
            "mean_of_means": float(niter_a[:, 0].mean()),
            "mean_of_max": float(niter_a[:, 2].mean()),
            "steps_with_a_world_at_limit": int((niter_a[:, 2] >= mjm.opt.iterations).sum()),
            "iterations_limit": int(mjm.opt.iterations),
            "tolerance": float(mjm.opt.tolerance),
        },
        "contacts": {"per_step_mean_max": ncon_a.round(3).tolist(), "max_per_world": int(ncon_a[:, 1].max())},
        "overflow_bits": overflow,
    }


def graph_rate(batch: int, tolerance: float | None, iterations: int | None, repeats: int = 2) -> dict:
    """Steps/s of the 160-step schedule as captured CUDA graphs (MuJoCo Warp without JAX)."""
    import mujoco.mjx.third_party.mujoco_warp as mjw
    import warp as wp

    scenario, mjm, m, d, qpos0 = _setup(batch, tolerance, iterations)
    ctrl = scenario.schedule.controls().astype(np.float32)
    cuda = wp.get_device().is_cuda
    if cuda:
        with wp.ScopedCapture() as cap:
            mjw.step(m, d)
    times = []
    for _ in range(repeats + 1):
        _reset(d, qpos0)
        wp.synchronize()
        t0 = time.perf_counter()
        last = None
        for u in ctrl:
            if last is None or not np.array_equal(u, last):
                d.ctrl.assign(np.tile(u, (batch, 1)))
                last = u
            wp.capture_launch(cap.graph) if cuda else mjw.step(m, d)
        wp.synchronize()
        times.append(time.perf_counter() - t0)
    run = float(np.median(times[1:]))
    it = d.solver_niter.numpy()
    return {"steps_per_second": round(batch * len(ctrl) / run, 1), "run_seconds": round(run, 4),
            "last_step_mean_iterations": float(it.mean()), "last_step_max_iterations": int(it.max())}


def mjx_rate(batch: int, tolerance: float | None, iterations: int | None, repeats: int = 2) -> dict:
    """Steps/s of this package's MJX-Warp rollout (jitted vmap of lax.scan) at the same settings."""
    from mjx_pusht.backends.mjx import MjxConfig, MjxRunner
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.reset import start_poses

    runner = MjxRunner(Scenario(), MjxConfig(impl="warp", tolerance=tolerance, iterations=iterations))
    seeds = np.arange(batch)
    poses = start_poses(seeds)
    runner.run(seeds, poses=poses)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = runner.run(seeds, poses=poses)
        times.append(time.perf_counter() - t0)
    run = float(np.median(times))
    return {"steps_per_second": round(batch * runner.scenario.schedule.total_steps / run, 1),
            "run_seconds": round(run, 4), "rigid_fraction": float(r.rigid.mean()),
            "final_y_mean": float(r.final[:, 1].mean())}


def contact_order(batch: int) -> dict:
    """One collision pass twice from one state: same contact set? same order in the buffer?"""
    import mujoco.mjx.third_party.mujoco_warp as mjw
    import warp as wp

    scenario, mjm, m, d, qpos0 = _setup(batch, None, None)
    ctrl = scenario.schedule.controls().astype(np.float32)
    _reset(d, qpos0)
    for u in ctrl[:80]:  # past first contact (median step 59) for most seeds
        d.ctrl.assign(np.tile(u, (batch, 1)))
        mjw.step(m, d)
    wp.synchronize()
    runs = []
    for _ in range(2):
        mjw.fwd_position(m, d)  # kinematics + collision from the same qpos
        wp.synchronize()
        n = int(d.nacon.numpy()[0])
        runs.append((d.contact.worldid.numpy()[:n].copy(), d.contact.geom.numpy()[:n].copy(),
                     d.contact.dist.numpy()[:n].copy(), d.contact.pos.numpy()[:n].copy()))
    (w1, g1, dist1, p1), (w2, g2, dist2, p2) = runs

    def canon(w, g, dist, p):
        keys = np.column_stack([w, g, np.round(p, 6)])
        return keys[np.lexsort(keys.T[::-1])]

    return {
        "nacon": [int(len(w1)), int(len(w2))],
        "same_order": bool(len(w1) == len(w2) and np.array_equal(w1, w2) and np.array_equal(g1, g2)
                           and np.array_equal(p1, p2)),
        "same_set": bool(len(w1) == len(w2) and np.array_equal(canon(w1, g1, dist1, p1), canon(w2, g2, dist2, p2))),
        "share_of_slots_that_moved": float(np.mean(w1 != w2)) if len(w1) == len(w2) else None,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--batch", type=int, default=65536)
    p.add_argument("--rate-batches", default=None, help="comma list for the rate table (default: --batch)")
    p.add_argument("--settings", default="default,tol=1e-6,tol=1e-5,iter=1",
                   help="solver settings for the rate table: default, tol=X, iter=N (iter=1 is a timing probe "
                        "of the solver's share, not a physics setting)")
    p.add_argument("--no-mjx", dest="mjx", action="store_false", help="skip the MJX rollout rates")
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)

    import warp as wp

    from mjx_pusht.backends.base import versions

    wp.init()
    out: dict = {"device": str(wp.get_device()), "device_name": wp.get_device().name, "versions": versions(),
                 "batch": a.batch}

    def save():
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(out, indent=1) + "\n")

    t0 = time.perf_counter()
    out["determinism"] = contact_order(min(a.batch, 4096))
    print("determinism", out["determinism"], flush=True)
    save()
    out["profile"] = profile(a.batch)
    prof = out["profile"]
    print("solver", {k: v for k, v in prof["solver"].items() if k != "per_step"}, flush=True)
    for k, v in list(prof["event_trace_share_of_step"].items()):
        print(f"  {k:60s} {v:7.1%}", flush=True)
    save()
    out["rates"] = []
    batches = [int(b) for b in (a.rate_batches or str(a.batch)).split(",")]
    for b in batches:
        for setting in a.settings.split(","):
            tol = float(setting[4:]) if setting.startswith("tol=") else None
            it = int(setting[5:]) if setting.startswith("iter=") else None
            row = {"batch": b, "setting": setting, "warp_graph": graph_rate(b, tol, it)}
            if a.mjx:
                row["mjx_scan"] = mjx_rate(b, tol, it)
            out["rates"].append(row)
            print("rate", row, flush=True)
            save()
    out["wall_seconds"] = round(time.perf_counter() - t0, 1)
    save()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
