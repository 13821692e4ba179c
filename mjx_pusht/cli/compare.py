"""`mjx-pusht compare`: MJX against MuJoCo C on the same seeds: open loop (the chapter's nudge), closed loop
(a controller's episodes), or two finished evals paired (--evals)."""

from __future__ import annotations

from pathlib import Path

from mjx_pusht.cli.parser import UsageError


def cmd_compare(args) -> int:
    from mjx_pusht.backends.base import IMPL, BackendError
    from mjx_pusht.io.banner import Banner
    from mjx_pusht.io.outputs import claim_out_dir
    from mjx_pusht.study.compare import compare
    from mjx_pusht.study.seeds import parse_seeds

    if args.evals:
        return _compare_evals(args)
    args.backend = args.backend or "mjx-jax"  # (None until here: --evals refuses one given)
    if not args.controller and (given := [f for f, v in (("--reset", args.reset), ("--max-steps", args.max_steps))
                                          if v is not None]):  # the open loop's nudge has its own starts and steps
        raise UsageError(f"{' and '.join(given)} set a controller's episodes: give --controller (expert: the task's "
                         "expert), or leave them out for the open-loop comparison")
    if args.controller and (given := [f for f, v in (("--tolerance", args.tolerance), ("--iterations", args.iterations),
                                                     ("--no-root-cause", not args.root_cause or None)) if v is not None]):
        raise UsageError(f"{' and '.join(given)} set the open-loop comparison (its MJX solver, its split-tee probe); "
                         "a controller's episodes run neither: leave them out, or leave out --controller")
    args.max_steps = args.max_steps or 300
    args.seeds = args.seeds or "64"  # the default, as the fingerprint of an earlier run holds it
    seeds = parse_seeds(args.seeds)
    from mjx_pusht.task.tasks import get as get_task

    task = get_task(args.task)
    others = ("mjx-jax", "mjx-warp", "gym-pusht") if task.name == "gym-pusht" else ("mjx-jax", "mjx-warp")
    if args.backend not in others:
        raise BackendError(f"compare --task {task.name} takes --backend {', '.join(others)}, not {args.backend!r}")
    if task.name != "chapter" and not args.controller:
        raise UsageError(f"compare --task {task.name} compares a controller's episodes: give --controller "
                         "(expert: the task's expert)")
    if (args.success_threshold is not None or args.goal != "fixed") and not args.controller:
        raise UsageError("--success-threshold and --goal are a controller's episodes': give --controller (the open-loop "
                         "comparison pushes toward no goal and scores no success)")
    reset = task.check_reset(args.reset)
    episode = task.episode(max_steps=args.max_steps, success_threshold=args.success_threshold, goal=args.goal)
    # a controller that cannot load is a one-line error before anything is written
    controller = task.controller(args.controller, goal=args.goal) if args.controller else None
    out = claim_out_dir(args.out, "compare", {**{k: getattr(args, k) for k in (
        "seeds", "backend", "controller", "max_steps", "root_cause", "tolerance", "iterations")}, "reset": reset,
        **({"task": task.name} if task.name != "chapter" else {}),
        **({"success_threshold": episode.success} if args.success_threshold is not None else {}),
        **({"goal": args.goal} if args.goal != "fixed" else {})}, replace=args.replace,
        share=args.share_out)
    banner = Banner("compare")
    if controller is not None:
        from mjx_pusht.backends.cpu import default_threads
        from mjx_pusht.study.closed_loop import compare_episodes
        r = compare_episodes(seeds, IMPL.get(args.backend, args.backend), out, controller=controller, task=task.name,
                             reset=reset, episode=episode, workers=default_threads())
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


def _compare_evals(args) -> int:
    from mjx_pusht.io.outputs import claim_out_dir

    if args.controller:
        raise UsageError("--evals pairs two finished evals; their controller is theirs, so --controller is not taken")
    if args.seeds is not None:
        raise UsageError("--evals pairs two finished evals; their seeds are theirs, so --seeds is not taken")
    given = [f for f, v in (("--max-steps", args.max_steps), ("--tolerance", args.tolerance),
                            ("--iterations", args.iterations), ("--task", args.task != "chapter" or None),
                            ("--backend", args.backend), ("--reset", args.reset), ("--goal", args.goal != "fixed" or None),
                            ("--success-threshold", args.success_threshold), ("--no-root-cause", not args.root_cause or None))
             if v is not None and v is not False]
    if given:  # the evals' own settings made their rows; nothing here runs
        raise UsageError(f"--evals pairs two finished evals and runs nothing, so {', '.join(given)} is not taken")
    from mjx_pusht.study.closed_loop import evals_report, write_report

    report = evals_report(*args.evals)  # a refused pairing leaves no --out folder behind
    out = claim_out_dir(args.out, "compare", {"evals": [str(p.resolve()) for p in args.evals]}, replace=args.replace,
                        reads=args.evals, share=args.share_out)
    _print_episodes(write_report(out, report), out)
    return 0


def _print_episodes(r: dict, out: Path) -> None:
    d = r["success_difference_mjx_minus_cpu"]
    print(f"success: cpu {r['cpu']['success_rate']:.2%}, {r['impl']} {r['mjx']['success_rate']:.2%} "
          f"(difference {d['difference']:+.2%}, 95% {d['ci95'][0]:+.2%} to {d['ci95'][1]:+.2%}); same verdict on "
          f"{r['per_seed_success_agreement']['mjx_vs_cpu']:.2%} of seeds")
    print(f"report: {out / 'compare_episodes.md'}\njson: {out / 'compare_episodes.json'}")
