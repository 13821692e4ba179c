"""`mjx-pusht scene` (one seed's nudge, its weld check and recording) and `mjx-pusht tree` (the body tree
MuJoCo compiled, or the collider table)."""

from __future__ import annotations

import numpy as np

from mjx_pusht.cli.parser import UsageError


def cmd_scene(args) -> int:
    from mjx_pusht.backends.cpu import CpuBackend
    from mjx_pusht.backends.results import scene_metrics
    from mjx_pusht.io.banner import Banner
    from mjx_pusht.io.outputs import atomic_write_json, claim_out_dir, drop_stale
    from mjx_pusht.model.scene import SceneSpec
    from mjx_pusht.model.tree import read_tree
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.schedule import SMOKE_NUDGE_STEPS, Schedule

    if args.smoke and args.steps is not None:
        raise UsageError(f"--smoke is the fixed {SMOKE_NUDGE_STEPS}-step run: leave --steps out, or drop --smoke")
    schedule = Schedule(nudge_steps=SMOKE_NUDGE_STEPS if args.smoke else args.steps or 120)
    if args.compare_welded and args.break_it == "none":
        raise UsageError("--compare-welded compares a broken scene with the welded one: give --break split-tee or free-tee")
    if args.compare_welded and not args.rerun:  # its one output is a recording (it wrote walk.rrd under --no-rerun,
        # the fourteenth pass)
        raise UsageError("--compare-welded records the welded and broken T side by side in walk.rrd, which --no-rerun "
                         "skips: give one")
    # one seed's look: a rerun with another seed may overwrite the last; other settings need --replace, and another
    # command's results are never overwritten
    out = claim_out_dir(args.out, "scene", {"steps": schedule.nudge_steps, "break": args.break_it,
                                            "compare_welded": args.compare_welded},
                        replace=args.replace, share=args.share_out)
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
        from mjx_pusht.io.record import record_run, viewer_command

        record_run(out / "scene.rrd", backend.model, run)
        print(f"recording: {out / 'scene.rrd'} - open it with: {viewer_command(out / 'scene.rrd')}")
    else:
        drop_stale(out / "scene.rrd")
    if args.compare_welded:
        from mjx_pusht.io.record import record_walk

        welded = CpuBackend(Scenario(SceneSpec("none"), schedule), nthread=1)
        w = welded.run(np.array([args.seed]), trace=True)
        record_walk(out / "walk.rrd", [("welded", welded.model, w), (args.break_it.replace("-", "_"), backend.model, run)])
        print(f"walk: welded gap settled at {w.gap_settled[0]:.4f} m, {args.break_it} at {run.gap_settled[0]:.4f} m; "
              f"recording: {out / 'walk.rrd'} - scrub sim_time to 0.40 s, the first settled frame")
    banner.done()
    return 0


def cmd_tree(args) -> int:
    from mjx_pusht.model.scene import SceneSpec, build_model
    from mjx_pusht.model.tree import read_tree, tree_json

    import json

    if args.colliders:
        import dataclasses

        from mjx_pusht.model.colliders import collider_table, describe

        rows = collider_table(args.break_it, pusher=args.pusher)
        print(json.dumps([dataclasses.asdict(r) for r in rows], indent=2) if args.json else describe(rows))
        return 0
    model = build_model(SceneSpec(args.break_it, args.pusher))
    tree, shape = read_tree(model), _pusher_shape(model)
    print(json.dumps({**json.loads(tree_json(tree)), "pusher": shape}, indent=2, sort_keys=True) if args.json
          else tree.describe() + f"\npusher shape: {shape}")
    return 0


def _pusher_shape(model) -> str:
    """The pusher's geom type as the compiled model holds it (`--pusher` read back, not echoed: the tree's bodies and
    joints are the same for every pusher, and its JSON was the same for both)."""
    import mujoco

    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "pusher")
    types = {mujoco.mjtGeom(int(t)).name.removeprefix("mjGEOM_").lower()
             for t, b in zip(model.geom_type, model.geom_bodyid) if b == body}
    return ", ".join(sorted(types))
