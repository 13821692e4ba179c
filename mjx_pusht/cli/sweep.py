"""`mjx-pusht sweep`: the chapter's study on many seeds (and a grid of parameters), on one backend or
several processes: per_seed.parquet, summary.json, an audit of a few rows on MuJoCo C, sweep.rrd."""

from __future__ import annotations

import sys
from pathlib import Path


def cmd_sweep(args) -> int:
    from mjx_pusht.backends.base import resolve
    from mjx_pusht.cli.parser import UsageError
    from mjx_pusht.io.outputs import atomic_write_json
    from mjx_pusht.model.params import parse_params
    from mjx_pusht.model.scene import SceneSpec
    from mjx_pusht.model.tree import read_tree
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.study.distributed import Processes
    from mjx_pusht.study.batch import record, start_batch, warn_mujoco
    from mjx_pusht.study.seeds import parse_seeds
    from mjx_pusht.study.sweep import finish, kept_chunks, run_sweep, summarize
    from mjx_pusht.task.schedule import Schedule

    seeds = parse_seeds(args.seeds)
    params = parse_params(args.param)
    processes = Processes(args.process_id, args.num_processes, args.coordinator, args.peer_timeout)
    processes.initialize()  # before anything asks JAX for its devices
    name, why = resolve(args.backend)
    if args.audit is not None and name == "cpu":  # the audit checks an MJX run against the CPU reference
        raise UsageError(f"--audit re-runs an MJX sweep's rows on the CPU reference; a {name} sweep is that reference: "
                         "leave --audit out")
    args.audit = 0.01 if args.audit is None else args.audit
    schedule = Schedule(nudge_steps=args.steps)
    config = {"backend": name, "break_it": args.break_it, "steps": args.steps, "params": [[n, list(v)] for n, v in params]}
    scenario = Scenario(SceneSpec(args.break_it), schedule, params, randomize=args.randomize)
    if params:  # checked on the scene before the folder is claimed: a refused flag leaves nothing behind
        from mjx_pusht.model.params import check_scene
        from mjx_pusht.model.scene import build_model

        check_scene(build_model(scenario.scene), params)
    if scenario.randomize:  # an unrandomised sweep's config (and so its fingerprint) stays as it was
        config["randomize"] = [[n, list(r)] for n, r in scenario.randomize]
    if processes.many:  # one sweep, one table: every process must have been given the same one
        from mjx_pusht.study.sweep import fingerprint, rows_for

        fp = fingerprint(rows_for(seeds, len(scenario.grid()))[0], config)
        # the folder's and the recording's flags too: process 0 alone claims and records, so a flag given to another
        # process alone (--resume, --replace) was ignored without a word (the fifteenth pass)
        processes.agree({**fp.pop("config"), **fp, "out": str(Path(args.out).resolve()), "resume": args.resume,
                         "replace": args.replace, "share_out": args.share_out, "rerun": args.rerun,
                         "record": args.record, "audit": args.audit})
    # process 0 claims the folder for all; its refusal (or any process's) ends every process, not process 0 alone
    row_seeds, combos, out, banner, clock, backend = processes.settled("start", lambda: start_batch(
        "sweep", args.out, seeds, name, why, config, scenario, replace=args.replace, resume=args.resume,
        check=processes.leader, share=args.share_out))
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
    try:  # a process's failure in its rows reaches the others in one line (they waited at a barrier for a day)
        run = processes.settled("rows", lambda: run_sweep(
            backend, row_seeds, out, config=config, chunk=args.chunk, resume=args.resume, progress=args.progress,
            combos=combos, on_start=auditor.start if auditor else None, processes=processes))
    except KeyboardInterrupt:
        print(f"\ninterrupted: {kept_chunks(out)}", file=sys.stderr)
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
    warn_mujoco(summary, "seeds")
    if summary["n_non_finite"]:
        print(f"WARNING: {summary['n_non_finite']} seeds went non-finite (flagged in per_seed.parquet, "
              f"left out of the statistics): {summary['non_finite_seeds'][:10]}")
    if summary["n_escaped"] and args.break_it != "free-tee":
        print(f"WARNING: {summary['n_escaped']} seeds left the walled workspace (a missed contact or a diverged "
              f"state; flagged in per_seed.parquet): {summary['escaped_seeds'][:10]}")
    if "success_rate" in summary["task"]:
        print(f"task score: {summary['task']['success_rate']:.1%} of seeds at coverage >= 0.95, after "
              f"{summary['task']['run']}")
    print(f"speed: {summary['steps_per_second']:,.0f} steps/s over {summary['run_seconds']:.2f} s "
          f"(+{summary['compile_seconds']:.2f} s compile)")
    print(f"table: {out / 'per_seed.parquet'}\nsummary: {out / 'summary.json'}")
    from mjx_pusht.io.record import record_sweep, recorded_rows

    record(out / "sweep.rrd", "seeds", backend, r, combos, lambda: recorded_rows(r, args.record), record_sweep,
           summary, clock, rerun=args.rerun, n=args.record)
    banner.done()
    return 0


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
