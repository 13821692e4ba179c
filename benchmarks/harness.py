"""Wall-clock benchmarks per hardware tier: every backend over batch sizes, in one process, in one run.

Writes benchmarks/results/<tier>.json and <tier>.png. Compile time is kept apart
from run time (first call minus the median of the timed repeats); the CPU's
single-thread mj_step rate and all-core rollout are measured beside the MJX
backends on the same host, so ratios never mix machines.

    python -m benchmarks.harness --tier cpu
    python -m benchmarks.harness --tier h100 --batches 4096,65536 --e2e 1000000
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
import traceback
from pathlib import Path

import mujoco
import numpy as np

from mjx_pusht.backends.base import versions
from mjx_pusht.backends.factory import make_backend
from mjx_pusht.io.banner import tier as tier_name
from mjx_pusht.scenario import Scenario

RESULTS = Path(__file__).parent / "results"


def single_thread_mj_step_rate(scenario: Scenario, seconds: float = 2.0) -> float:
    """Steps/s of a bare mj_step loop on one core over the seed-0 schedule, repeated."""
    from mjx_pusht.model.layout import QposLayout
    from mjx_pusht.model.scene import build_model
    from mjx_pusht.task.reset import start_poses

    model = build_model(scenario.scene)
    data = mujoco.MjData(model)
    qpos0 = QposLayout.of(model).initial_qpos(model, start_poses([0]))[0]
    ctrl = scenario.schedule.controls()
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        mujoco.mj_resetData(model, data)
        data.qpos[:] = qpos0
        for u in ctrl:
            data.ctrl[:] = u
            mujoco.mj_step(model, data)
        steps += len(ctrl)
    return steps / (time.perf_counter() - t0)


def measure(backend, batch: int, repeats: int, total_steps: int) -> dict:
    from mjx_pusht.task.reset import start_poses

    seeds = np.arange(batch)
    scenario = getattr(backend, "scenario", None)
    # host-side set-up, timed by the end-to-end run, not here
    poses = start_poses(seeds, reset=scenario.reset if scenario is not None else "chapter")
    t0 = time.perf_counter()
    backend.run(seeds, batch=batch, poses=poses)
    first = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        backend.run(seeds, batch=batch, poses=poses)
        times.append(time.perf_counter() - t0)
    run = statistics.median(times)
    return {
        "batch": batch,
        "first_call_seconds": round(first, 4),
        "compile_seconds": round(max(first - run, 0.0), 4),
        "run_seconds_median": round(run, 5),
        "run_seconds_all": [round(t, 5) for t in times],
        "steps_per_second": round(batch * total_steps / run, 1),
        "includes_start_poses": False,
    }


def end_to_end(name: str, scenario: Scenario, n: int, chunk: int | None) -> dict:
    """A whole sweep as a user runs it: start poses, compile, rollout, per_seed.parquet written."""
    from mjx_pusht.study.sweep import finish, run_sweep

    t0 = time.perf_counter()
    backend = make_backend(name, scenario)
    with tempfile.TemporaryDirectory() as d:
        run = run_sweep(backend, np.arange(n), Path(d), config={"bench": name}, chunk=chunk, progress=False)
        finish(Path(d), run)
        size = (Path(d) / "per_seed.parquet").stat().st_size
    wall = time.perf_counter() - t0
    return {"backend": name, "device": backend.device, "n_seeds": n, "wall_seconds": round(wall, 2), "compile_seconds": round(run.compile_seconds, 2),
            "warp_buffers": getattr(backend, "buffer_info", None),
            "rigid_fraction": float(run.rollouts.rigid.mean()), "parquet_bytes": size,
            "steps_per_second_end_to_end": round(n * scenario.schedule.total_steps / wall, 1)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tier", default="cpu", help="name of the results file (cpu, h100, h200, ...)")
    p.add_argument("--backends", default="cpu,mjx-jax,mjx-warp")
    p.add_argument("--batches", default=None, help="comma list for every backend (default: by tier)")
    p.add_argument("--cpu-batches", default=None)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--e2e", type=int, default=0, help="also time an end-to-end sweep of this many seeds")
    p.add_argument("--e2e-backend", default="auto")
    p.add_argument("--e2e-chunk", type=int, default=None)
    p.add_argument("--device-counts", default="1",
                   help="comma list: run each MJX backend sharded over the first K devices too (e.g. 1,2)")
    p.add_argument("--warp-buffers", default=None, metavar="C,R",
                   help="fix MJX-Warp's contacts and constraint rows per world (default: start small, grow on overflow)")
    p.add_argument("--closed-loop", type=int, default=0, metavar="STEPS",
                   help="also run each MJX backend with the expert in the scan on task starts for STEPS control steps "
                        "(10 physics steps each, no early exit), beside the open-loop rows of the same run")
    p.add_argument("--box-box-both", action="store_true",
                   help="also run mjx-warp with MuJoCo Warp's default GJK/EPA box-box (mjx-warp-gjk-box-box), "
                        "beside the primitive box_box that matches MuJoCo C")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    mjx_opts = {}
    if args.warp_buffers:
        c, r = (int(x) for x in args.warp_buffers.split(","))
        mjx_opts = {"contacts_per_world": c, "constraints_per_world": r}
    scenario = Scenario()
    total = scenario.schedule.total_steps
    on_cpu = args.tier == "cpu"
    default = "1024,4096" if on_cpu else "1024,4096,16384,65536"
    mjx_batches = [int(b) for b in (args.batches or ("64,256" if on_cpu else default)).split(",")]
    cpu_batches = [int(b) for b in (args.cpu_batches or args.batches or default).split(",")]
    result = {"tier": args.tier, "device": tier_name(), "versions": versions(), "total_steps": total,
              "date": time.strftime("%Y-%m-%d"), "scene": "welded, 40 settle + 120 nudge steps", "backends": {}}
    result["cpu_single_thread_mj_step_per_second"] = round(single_thread_mj_step_rate(scenario), 1)
    print(f"single-thread mj_step: {result['cpu_single_thread_mj_step_per_second']:,.0f} steps/s", flush=True)
    counts = [int(k) for k in args.device_counts.split(",")]
    for name in args.backends.split(","):
        for k in ([1] if name == "cpu" else counts):
            key = name if k == 1 else f"{name}-x{k}"
            result["backends"][key] = measure_backend(name, scenario, cpu_batches if name == "cpu" else mjx_batches,
                                                      args.repeats, total, devices=k,
                                                      **(mjx_opts if name == "mjx-warp" else {}))
    if args.box_box_both and "mjx-warp" in args.backends.split(","):
        result["backends"]["mjx-warp-gjk-box-box"] = measure_backend(
            "mjx-warp", scenario, mjx_batches, args.repeats, total, **{**mjx_opts, "match_c_colliders": False})
    if args.closed_loop:
        add_closed_loop(result, args, mjx_batches, mjx_opts)
    add_scaling(result)
    if args.e2e:
        result["end_to_end"] = end_to_end(resolve_auto(args.e2e_backend), scenario, args.e2e, args.e2e_chunk)
        print(f"end to end: {result['end_to_end']}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"{args.tier}.json"
    path.write_text(json.dumps(result, indent=2) + "\n")
    plot(result, args.out / f"{args.tier}.png")
    print(f"wrote {path}")
    return 0


def measure_backend(name: str, scenario: Scenario, batches: list[int], repeats: int, total: int,
                    devices: int = 1, **kwargs) -> dict:
    """One backend over batch sizes; errors (cannot run here, out of memory) are recorded as results."""
    if name.startswith("mjx-"):
        import jax

        if len(jax.devices()) < devices:
            return {"error": f"{devices} devices asked for, {len(jax.devices())} present"}
        kwargs["devices"] = jax.devices()[:devices]  # explicit: a backend left alone takes every device
    label = name if devices == 1 else f"{name} x{devices}"
    try:
        backend = make_backend(name, scenario, **kwargs)
    except Exception as e:  # noqa: BLE001 - a backend that cannot run here is recorded, not fatal
        print(f"{label}: cannot run here: {e}", flush=True)
        return {"error": f"{type(e).__name__}: {e}"}
    rows = []
    for batch in batches:
        try:
            row = measure(backend, batch, repeats, total)
        except Exception as e:  # noqa: BLE001 - out of memory at a size is a result too
            row = {"batch": batch, "error": f"{type(e).__name__}: {str(e).splitlines()[0][:300]}"}
            traceback.print_exc(limit=1)
        rows.append(row)
        print(f"{label} batch {batch}: {row.get('steps_per_second', row.get('error'))}", flush=True)
    out = {"device": backend.device, "pusher": backend.pusher, "devices": devices, "rows": rows,
           "warp_buffers": getattr(backend, "buffer_info", None)}
    if name == "cpu":
        out["threads"] = backend.nthread
    return out


def add_closed_loop(result: dict, args, batches: list[int], mjx_opts: dict) -> None:
    """The expert inside the compiled scan: `<backend>-expert` rows, and their rate over the open-loop rate."""
    from mjx_pusht.task.controllers import Expert
    from mjx_pusht.task.episode import Episode

    episode = Episode(max_steps=args.closed_loop)
    closed = Scenario(reset="task", controller=Expert(), episode=episode)
    for name in args.backends.split(","):
        if not name.startswith("mjx-"):
            continue
        key = f"{name}-expert"
        result["backends"][key] = b = measure_backend(name, closed, batches, args.repeats, episode.physics_steps,
                                                      **(mjx_opts if name == "mjx-warp" else {}))
        b["scenario"] = f"expert on task starts, {args.closed_loop} control steps x 10 physics steps"
        open_rows = {r["batch"]: r["steps_per_second"] for r in result["backends"].get(name, {}).get("rows", [])
                     if "steps_per_second" in r}
        b["rate_over_open_loop"] = {str(r["batch"]): round(r["steps_per_second"] / open_rows[r["batch"]], 3)
                                    for r in b.get("rows", []) if "steps_per_second" in r and r["batch"] in open_rows}
        print(f"{key}: closed-loop rate / open-loop rate = {b['rate_over_open_loop']}", flush=True)


def add_scaling(result: dict) -> None:
    """Scaling efficiency of each sharded entry: its steps/s over K x the one-device rate, per batch."""
    for key, b in result["backends"].items():
        k = b.get("devices", 1)
        base = result["backends"].get(key.rsplit("-x", 1)[0]) if k > 1 else None
        if not base or "rows" not in base or "rows" not in b:
            continue
        one = {r["batch"]: r["steps_per_second"] for r in base["rows"] if "steps_per_second" in r}
        b["scaling_efficiency"] = {str(r["batch"]): round(r["steps_per_second"] / (k * one[r["batch"]]), 3)
                                   for r in b["rows"] if "steps_per_second" in r and r["batch"] in one}


def resolve_auto(name: str) -> str:
    from mjx_pusht.backends.base import resolve

    return resolve(name)[0]


def plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for name, b in result["backends"].items():
        rows = [r for r in b.get("rows", []) if "steps_per_second" in r]
        if rows:
            ax.plot([r["batch"] for r in rows], [r["steps_per_second"] for r in rows], "o-", label=f"{name} ({b['device']})")
    ax.set(xscale="log", yscale="log", xlabel="batch (seeds)", ylabel="steps / s",
           title=f"PushT rollout throughput, tier {result['tier']} ({result['device']})")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
