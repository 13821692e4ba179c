"""The `mjx-pusht` commands: each a thin layer over the library (scene, tree, sweep, eval, compare)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from mjx_pusht.cli.parser import UsageError, build_parser
from mjx_pusht.errors import MjxPushtError


class Clock:
    """Seconds per phase of a command, for summary.json's `timing` block."""

    def __init__(self):
        import time

        self._now = time.perf_counter
        self.t = self._now()
        self.laps: dict[str, float] = {}

    def lap(self, name: str) -> float:
        t = self._now()
        self.laps[name] = t - self.t
        self.t = t
        return self.laps[name]

    def report(self, sweep: dict) -> dict:
        """The command's phases, with the sweep's own (start poses, compile, rollout, writing) inside it."""
        out = {k: round(v, 3) for k, v in self.laps.items()}
        out.update({f"sweep.{k}": round(v, 3) for k, v in sweep.items() if k != "rollout_and_compile"})
        return out


def cmd_compare(args) -> int:
    from mjx_pusht.backends.base import IMPL, BackendError
    from mjx_pusht.cli.banner import Banner
    from mjx_pusht.io.outputs import claim_out_dir
    from mjx_pusht.study.compare import compare
    from mjx_pusht.study.seeds import parse_seeds

    if args.evals:
        return _compare_evals(args)
    seeds = parse_seeds(args.seeds)
    if args.backend not in ("mjx-jax", "mjx-warp"):
        raise BackendError(f"compare takes --backend mjx-jax or mjx-warp, not {args.backend!r}")
    controller = None
    if args.controller:  # a controller that cannot load is a one-line error before anything is written
        from mjx_pusht.task.controllers import load

        controller = load(args.controller)
    out = claim_out_dir(args.out, "compare", {k: getattr(args, k) for k in (
        "seeds", "backend", "controller", "reset", "max_steps", "root_cause", "tolerance", "iterations")},
        replace=args.replace)
    banner = Banner("compare")
    if controller is not None:
        from mjx_pusht.backends.cpu import default_threads
        from mjx_pusht.study.closed_loop import compare_episodes
        from mjx_pusht.task.episode import Episode

        r = compare_episodes(seeds, IMPL[args.backend], out, controller=controller,
                             reset=args.reset, episode=Episode(max_steps=args.max_steps), workers=default_threads())
        _print_episodes(r, out)
        banner.done()
        return 0
    opts = {k: v for k, v in (("tolerance", args.tolerance), ("iterations", args.iterations)) if v is not None}
    r = compare(seeds, IMPL[args.backend], out, root_cause=args.root_cause, mjx_options=opts)
    w = r["none"]
    print(f"settle_max_abs_err {w['settle_max_abs_err']:.2e} (split-tee {r['split-tee']['settle_max_abs_err']:.2e}); "
          f"verdict_agreement {w['verdict_agreement']:.3f} (split-tee {r['split-tee']['verdict_agreement']:.3f})")
    print(f"outcome_within_cpu_baseline: {r['outcomes']['outcome_within_cpu_baseline']}")
    print(f"report: {out / 'compare.md'}\njson: {out / 'compare.json'}\nplot: {out / 'compare.png'}")
    banner.done()
    return 0


def cmd_tree(args) -> int:
    from mjx_pusht.model.scene import SceneSpec, build_model
    from mjx_pusht.model.tree import read_tree, tree_json

    if args.colliders:
        import dataclasses
        import json

        from mjx_pusht.model.colliders import collider_table, describe

        rows = collider_table(args.break_it)
        print(json.dumps([dataclasses.asdict(r) for r in rows], indent=2) if args.json else describe(rows))
        return 0
    tree = read_tree(build_model(SceneSpec(args.break_it, args.pusher)))
    print(tree_json(tree) if args.json else tree.describe() + f"\npusher shape: {args.pusher}")
    return 0


def cmd_scene(args) -> int:
    from mjx_pusht.backends.cpu import CpuBackend
    from mjx_pusht.backends.results import scene_metrics
    from mjx_pusht.cli.banner import Banner
    from mjx_pusht.io.outputs import atomic_write_json, claim_out_dir, drop_stale
    from mjx_pusht.model.scene import SceneSpec
    from mjx_pusht.model.tree import read_tree
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.schedule import SMOKE_NUDGE_STEPS, Schedule

    schedule = Schedule(nudge_steps=SMOKE_NUDGE_STEPS if args.smoke else args.steps)
    if args.compare_welded and args.break_it == "none":
        raise UsageError("--compare-welded compares a broken scene with the welded one: give --break split-tee or free-tee")
    # one seed's look: a rerun with another seed may overwrite the last; another command's results may not
    out = claim_out_dir(args.out, "scene", {}, replace=args.replace)
    banner = Banner("scene")
    scenario = Scenario(SceneSpec(args.break_it), schedule)
    backend = CpuBackend(scenario, nthread=1)
    tree = read_tree(backend.model)
    print(tree.describe())
    run = backend.run(np.array([args.seed]), trace=args.rerun)
    metrics = scene_metrics(run, 0, tree, args.break_it)
    atomic_write_json(out / "metrics.json", metrics)
    print(f"nudge: pusher drove block from y={run.settled[0, 1]:.3f} to y={run.final[0, 1]:.3f}")
    verdict = "RIGID" if metrics["tee_stayed_rigid"] else "SPLIT - never one rigid body"
    print(f"weld check: bar-stem gap settled at {run.gap_settled[0]:.4f} m, peak deviation "
          f"{run.gap_max_dev[0]:.4f} m from the 0.06 weld ({verdict})")
    print(f"metrics: {out / 'metrics.json'}")
    if args.rerun:
        from mjx_pusht.io.record import record_run

        record_run(out / "scene.rrd", backend.model, run)
        print(f"recording: {out / 'scene.rrd'} - open it with: rerun {out / 'scene.rrd'}")
    else:
        drop_stale(out / "scene.rrd")
    if args.compare_welded:
        from mjx_pusht.io.record import record_walk

        welded = CpuBackend(Scenario(SceneSpec("none"), schedule), nthread=1)
        w = welded.run(np.array([args.seed]), trace=True)
        if not args.rerun:
            run = backend.run(np.array([args.seed]), trace=True)
        record_walk(out / "walk.rrd", [("welded", welded.model, w), (args.break_it.replace("-", "_"), backend.model, run)])
        print(f"walk: welded gap settled at {w.gap_settled[0]:.4f} m, {args.break_it} at {run.gap_settled[0]:.4f} m; "
              f"recording: {out / 'walk.rrd'} - scrub sim_time to 0.40 s, the first settled frame")
    banner.done()
    return 0


def cmd_sweep(args) -> int:
    from mjx_pusht.backends.base import resolve
    from mjx_pusht.io.outputs import atomic_write_json
    from mjx_pusht.model.params import parse_param
    from mjx_pusht.model.scene import SceneSpec
    from mjx_pusht.model.tree import read_tree
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.study.distributed import Processes
    from mjx_pusht.study.seeds import parse_seeds
    from mjx_pusht.study.sweep import finish, run_sweep, summarize
    from mjx_pusht.task.schedule import Schedule

    seeds = parse_seeds(args.seeds)
    params = tuple((n, tuple(v)) for n, v in (parse_param(t) for t in args.param))
    if len({n for n, _ in params}) != len(params):
        raise UsageError("each --param NAME may be given once")
    processes = Processes(args.process_id, args.num_processes, args.coordinator, args.peer_timeout)
    processes.initialize()  # before anything asks JAX for its devices
    name, why = resolve(args.backend)
    schedule = Schedule(nudge_steps=args.steps)
    config = {"backend": name, "break_it": args.break_it, "steps": args.steps, "params": [[n, list(v)] for n, v in params]}
    scenario = Scenario(SceneSpec(args.break_it), schedule, params)
    if processes.many:  # one sweep, one table: every process must have been given the same one
        from mjx_pusht.study.sweep import fingerprint, rows_for

        fp = fingerprint(rows_for(seeds, len(scenario.grid()))[0], config)
        processes.agree({**fp.pop("config"), **fp, "out": str(Path(args.out).resolve())})
    row_seeds, combos, out, banner, clock, backend = _start_batch("sweep", args, seeds, name, why, config, scenario,
                                                                  check=processes.leader)
    print(read_tree(backend.model).describe())
    print(f"pusher shape simulated: {backend.pusher}" + (" (substituted: MJX's JAX backend has no cylinder-box collision)"
                                                          if backend.pusher != scenario.scene.pusher else ""))
    print(f"device: {backend.device}; {len(seeds)} seeds x {schedule.total_steps} steps "
          f"({schedule.settle_steps} settle + {schedule.nudge_steps} nudge)"
          + (f" x {len(scenario.grid())} parameter combinations ({', '.join(n for n, _ in params)})" if params else ""))
    auditor = None
    if name != "cpu" and args.audit > 0 and processes.leader:
        from mjx_pusht.study.audit import Audit

        auditor = Audit(backend, row_seeds, combos, args.audit)  # its CPU rows run beside the device's
    try:
        run = run_sweep(backend, row_seeds, out, config=config, chunk=args.chunk, resume=args.resume,
                        progress=args.progress, combos=combos, on_start=auditor.start if auditor else None,
                        processes=processes)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished chunks are kept in {out}; rerun with --resume to finish", file=sys.stderr)
        return 130
    if processes.many:
        run = _join_processes(processes, run, out, row_seeds)
        if not processes.leader:
            lo, hi = processes.block(len(row_seeds))
            print(f"process {processes.process_id}: rows {lo}..{hi - 1} written to {out / '.parts'}; "
                  "process 0 writes the table")
            banner.done()
            return 0
    clock.lap("sweep")
    summary = summarize(run.rollouts, backend=backend, schedule=schedule, break_it=args.break_it,
                        compile_s=run.compile_seconds, run_s=run.run_seconds, table=run.table)
    finish(out, run)
    clock.lap("table_writing")
    summary["timing"] = clock.report(run.timing)
    if auditor is not None:
        from mjx_pusht.study.audit import announce

        summary["audit"] = auditor.finish(run.rollouts, welded=args.break_it == "none", out=out)
        summary["timing"]["audit_wait"] = round(clock.lap("audit_wait"), 3)  # what the overlap did not hide
    elif name != "cpu":
        summary["audit"] = {"skipped": "--audit 0"}
    atomic_write_json(out / "summary.json", summary)
    if "agrees" in summary.get("audit", {}):
        announce(summary["audit"])
    r = run.rollouts
    print(f"weld check: {summary['n_rigid']} of {len(r)} seeds RIGID ({summary['rigid_fraction']:.1%}), "
          f"{len(r) - summary['n_rigid'] - summary['n_mujoco_warnings']} SPLIT; non-finite: {summary['n_non_finite']}"
          + (f"; MuJoCo warned on {summary['n_mujoco_warnings']}" if summary["n_mujoco_warnings"] else ""))
    _warn_mujoco(summary, "seeds")
    if summary["n_non_finite"]:
        print(f"WARNING: {summary['n_non_finite']} seeds went non-finite (flagged in per_seed.parquet, "
              f"left out of the statistics): {summary['non_finite_seeds'][:10]}")
    if summary["n_escaped"] and args.break_it != "free-tee":
        print(f"WARNING: {summary['n_escaped']} seeds left the walled workspace (a missed contact or a diverged "
              f"state; flagged in per_seed.parquet): {summary['escaped_seeds'][:10]}")
    print(f"speed: {summary['steps_per_second']:,.0f} steps/s over {summary['run_seconds']:.2f} s "
          f"(+{summary['compile_seconds']:.2f} s compile)")
    print(f"table: {out / 'per_seed.parquet'}\nsummary: {out / 'summary.json'}")
    from mjx_pusht.io.record import record_sweep, recorded_rows

    _record(args, out / "sweep.rrd", "seeds", backend, r, combos, lambda: recorded_rows(r, args.record),
            record_sweep, summary, clock)
    banner.done()
    return 0


def _warn_mujoco(summary: dict, rows: str) -> None:
    if summary["n_mujoco_warnings"]:
        print(f"WARNING: MuJoCo raised {', '.join(summary['mujoco_warnings'])} on {summary['n_mujoco_warnings']} {rows} "
              f"(flagged in mujoco_warnings, never counted rigid; mjWARN_INERTIA: a singular model, e.g. a "
              f"near-zero mass): {summary['mujoco_warning_seeds'][:10]}")


def _join_processes(processes, run, out: Path, row_seeds):
    """Wait for every process's chunks; process 0 then holds the whole sweep's table, read from them."""
    import dataclasses
    import time

    from mjx_pusht.study.sweep import PARTS, assemble

    t0 = time.perf_counter()
    processes.barrier("chunks-written")
    waited = time.perf_counter() - t0
    if not processes.leader:
        return run
    table, rollouts = assemble(out / PARTS, row_seeds, None, 0)
    timing = {**run.timing, "waiting_for_other_processes": waited}
    return dataclasses.replace(run, rollouts=rollouts, table=table, run_seconds=run.run_seconds + waited, timing=timing)


def _start_batch(command: str, args, seeds, name: str, why: str, config: dict, scenario, check: bool = True):
    """What every batch command does before its first row: the rows, a writable --out that holds no
    other unfinished run, the banner, and the backend (which compiles the scene and checks its tree)."""
    from mjx_pusht.backends.base import make_backend
    from mjx_pusht.backends.cpu import default_threads
    from mjx_pusht.cli.banner import Banner
    from mjx_pusht.io.outputs import claim_out_dir, prepare_out_dir
    from mjx_pusht.study.sweep import check_resumable, fingerprint, rows_for

    row_seeds, combos = rows_for(seeds, len(scenario.grid()))
    out = prepare_out_dir(args.out)
    if check:  # with several processes, process 0 checks, locks (and clears) the folder for all
        claim_out_dir(out, command, fingerprint(row_seeds, config), replace=args.replace)
        check_resumable(out, row_seeds, config, args.resume)
    banner = Banner(command)
    print(f"backend: {name} ({why})")
    clock = Clock()
    # cpu: feedback episodes take a process per core (the sweep's open-loop rollout threads itself)
    backend = make_backend(name, scenario, workers=default_threads() if command == "eval" else 1)
    clock.lap("backend_setup_and_tree_check")
    return row_seeds, combos, out, banner, clock, backend


def _record(args, path: Path, rows: str, backend, r, combos, pick, writer, summary: dict, clock) -> None:
    """The recording of a batch command: the picked rows rerun with a trace and written by `writer`
    (or an earlier run's recording removed when this run is not recorded); its time joins the summary."""
    from mjx_pusht.io.outputs import atomic_write_json, drop_stale
    from mjx_pusht.io.record import row_labels

    if not (args.rerun and args.record > 0):
        drop_stale(path)
        return
    shown = pick()
    traced = backend.run(r.seeds[shown], trace=True, combos=combos[shown])
    writer(path, backend.model, traced, r, row_labels(r, shown))
    summary["timing"]["recording"] = round(clock.lap("recording"), 3)
    atomic_write_json(path.parent / "summary.json", summary)
    print(f"recording: {path} ({len(shown)} {rows} side by side) - open it with: rerun {path}")


def _video(args, backend, r, combos, episode, summary: dict, clock) -> None:
    """The first episodes rerun with a trace and drawn as a grid of tiles (video.py)."""
    from mjx_pusht.io.outputs import atomic_write_json
    from mjx_pusht.io.video import episode_grid, write
    from mjx_pusht.model.layout import QposLayout

    shown = np.arange(min(args.video_episodes, len(r)))
    traced = backend.run(r.seeds[shown], trace=True, combos=combos[shown])
    # the video ends a second after the last shown episode does
    last = min(int(np.max(traced.episode["length"])) + 10, episode.max_steps)
    frames = episode_grid(backend.model, traced.trace.qpos[:, : last * episode.frame_skip + 1],
                          QposLayout.of(backend.model), r.seeds[shown], episode.frame_skip, episode.success,
                          args.video_size)
    fps = 1 / (episode.frame_skip * traced.trace.dt)
    write(args.video, frames, fps)
    summary["timing"]["video"] = round(clock.lap("video"), 3)
    atomic_write_json(Path(args.out) / "summary.json", summary)
    print(f"video: {args.video} ({len(shown)} episodes, {len(frames)} frames at {fps:g} per second)")


def _compare_evals(args) -> int:
    from mjx_pusht.io.outputs import claim_out_dir

    if args.controller:
        raise UsageError("--evals pairs two finished evals; their controller is theirs, so --controller is not taken")
    from mjx_pusht.study.closed_loop import evals_report, write_report

    report = evals_report(*args.evals)  # a refused pairing leaves no --out folder behind
    out = claim_out_dir(args.out, "compare", {"evals": [str(p.resolve()) for p in args.evals]}, replace=args.replace)
    _print_episodes(write_report(out, report), out)
    return 0


def _print_episodes(r: dict, out: Path) -> None:
    d = r["success_difference_mjx_minus_cpu"]
    print(f"success: cpu {r['cpu']['success_rate']:.2%}, {r['impl']} {r['mjx']['success_rate']:.2%} "
          f"(difference {d['difference']:+.2%}, 95% {d['ci95'][0]:+.2%} to {d['ci95'][1]:+.2%}); same verdict on "
          f"{r['per_seed_success_agreement']['mjx_vs_cpu']:.2%} of seeds")
    print(f"report: {out / 'compare_episodes.md'}\njson: {out / 'compare_episodes.json'}")


def _policy_sha256(spec: str) -> str | None:
    """A trained policy's file, by content: what `compare --evals` checks before it pairs two evals' rows
    (the same path on two machines can hold other weights). None for the built-in controllers."""
    if not spec.startswith("policy:"):
        return None
    import hashlib

    return hashlib.sha256(Path(spec.removeprefix("policy:")).read_bytes()).hexdigest()


def cmd_eval(args) -> int:
    from mjx_pusht.backends.base import resolve
    from mjx_pusht.io.outputs import atomic_write_json
    from mjx_pusht.model.params import parse_param
    from mjx_pusht.model.scene import SceneSpec
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.study.seeds import parse_seeds
    from mjx_pusht.study.stats import summarize_episodes
    from mjx_pusht.study.sweep import finish, run_sweep
    from mjx_pusht.task.controllers import describe, load
    from mjx_pusht.task.episode import Episode

    seeds = parse_seeds(args.seeds)
    params = tuple((n, tuple(v)) for n, v in (parse_param(t) for t in args.param))
    if len({n for n, _ in params}) != len(params):
        raise UsageError("each --param NAME may be given once")
    episode = Episode(frame_skip=args.frame_skip, max_steps=args.max_steps)
    controller = load(args.controller, action_type=args.action, frame_skip=args.frame_skip)
    if args.video is not None:
        from mjx_pusht.io.video import check_path

        check_path(args.video)  # a bad name or a missing encoder fails now, not after the episodes
    name, why = resolve(args.backend)
    config = {"command": "eval", "backend": name, "controller": args.controller, "action": controller.action_type,
              "reset": args.reset, "break_it": args.break_it, "max_steps": args.max_steps,
              "frame_skip": args.frame_skip, "params": [[n, list(v)] for n, v in params],
              "controller_sha256": _policy_sha256(args.controller)}
    scenario = Scenario(SceneSpec(args.break_it), params=params, reset=args.reset, controller=controller, episode=episode)
    row_seeds, combos, out, banner, clock, backend = _start_batch("eval", args, seeds, name, why, config, scenario)
    from mjx_pusht.backends.cpu import default_threads

    print(f"controller: {describe(controller)}; reset: {args.reset}; {len(seeds)} episodes of at most "
          f"{args.max_steps} control steps x {args.frame_skip} physics steps; device: {backend.device}; "
          f"pusher shape: {backend.pusher}")
    # small chunks on the CPU keep the progress bar (and --resume) fine-grained
    chunk = args.chunk or (128 * default_threads() if name == "cpu" else None)
    try:
        run = run_sweep(backend, row_seeds, out, config=config, chunk=chunk, resume=args.resume,
                        progress=args.progress, combos=combos, episodes=True)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished chunks are kept in {out}; rerun with --resume to finish", file=sys.stderr)
        return 130
    finally:
        backend.close()
    clock.lap("episodes")
    r = run.rollouts
    from mjx_pusht.backends.base import versions

    summary = {"config": config, **backend.describe(), "versions": versions(), "controller": describe(controller),
               "success_coverage": episode.success, **summarize_episodes(r),
               "compile_seconds": round(run.compile_seconds, 3), "run_seconds": round(run.run_seconds, 3)}
    finish(out, run, name="per_episode.parquet", episodes=True)
    clock.lap("table_writing")
    summary["timing"] = clock.report(run.timing)
    atomic_write_json(out / "summary.json", summary)
    lo, hi = summary["success_rate_ci95"]
    print(f"success: {summary['n_success']} of {summary['n_finite']} episodes ({summary['success_rate']:.1%}, "
          f"95% interval {lo:.1%}-{hi:.1%}); median steps to success {summary['median_steps_to_success']}; "
          f"median final coverage {summary['final_coverage'].get('median', float('nan')):.3f}")
    _warn_mujoco(summary, "episodes")
    if summary["n_non_finite"]:
        print(f"WARNING: {summary['n_non_finite']} episodes went non-finite (flagged, left out of the rate): "
              f"{summary['non_finite_seeds'][:10]}")
    if summary["n_escaped"] and args.break_it != "free-tee":
        print(f"WARNING: {summary['n_escaped']} episodes left the walled workspace: {summary['escaped_seeds'][:10]}")
    if args.break_it == "none" and summary["n_rigid"] + summary["n_mujoco_warnings"] != len(r):
        print(f"WARNING: the welded T came apart in {len(r) - summary['n_rigid'] - summary['n_mujoco_warnings']} episodes")
    print(f"table: {out / 'per_episode.parquet'}\nsummary: {out / 'summary.json'}")
    from mjx_pusht.io.record import record_episodes

    _record(args, out / "eval.rrd", "episodes", backend, r, combos, lambda: np.arange(min(args.record, len(r))),
            record_episodes, summary, clock)
    if args.video is not None:
        _video(args, backend, r, combos, episode, summary, clock)
    banner.done()
    return 0


def cmd_train(args) -> int:
    try:
        from mjx_pusht.train.run import cmd_train as train
    except ImportError as e:
        raise UsageError(f"train needs the training extra ({e.name} is missing): pip install 'mjx-pusht[train]'") from None
    return train(args)


COMMANDS = {"scene": cmd_scene, "tree": cmd_tree, "sweep": cmd_sweep, "eval": cmd_eval, "compare": cmd_compare,
            "train": cmd_train}


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input (an `MjxPushtError`) is one line and a non-zero exit; anything else is a bug
    and keeps its traceback."""
    from mjx_pusht.io.outputs import held_folders

    try:
        args = build_parser().parse_args(argv)
        if args.verbose:
            os.environ["MJX_PUSHT_VERBOSE"] = "1"
        with held_folders():  # the --out folder is locked while the command runs
            return COMMANDS[args.command](args)
    except UsageError as e:
        print(f"mjx-pusht: error: {e}", file=sys.stderr)
        return 2
    except MjxPushtError as e:
        print(f"mjx-pusht: error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
