"""`mjx-pusht demos`: a controller's episodes on the gym-pusht drop-in, written as a LeRobot dataset
(`io.demos.write_demos`), and the lerobot-train command that reads it."""

from __future__ import annotations

from pathlib import Path


def add_parser(sub, *, rows, steps, folder, replace_help: str, share_help: str, success) -> None:
    d = sub.add_parser("demos", help="a controller's episodes on the gym-pusht drop-in as a LeRobot dataset "
                                     "(lerobot-train --dataset.root)")
    d.add_argument("--seeds", default="100", help="N (0..N-1), A:B, or a,b,c: one episode per seed, episode i from "
                                                  "the i-th seed's gym-pusht start (default 100)")
    d.add_argument("--controller", default="expert",
                   help="expert (default: gym-pusht's task's expert), zero, random, a trained policy as policy:PATH, or "
                        "your own as package.module:function (its velocities become gym-pusht targets, pusher + 0.2 s x v)")
    d.add_argument("--task", choices=("gym-pusht", "gym-pusht-easy"), default="gym-pusht",
                   help="gym-pusht (default: its starts) or gym-pusht-easy (the T a few cm off the target)")
    d.add_argument("--successful-only", action="store_true",
                   help="write only the episodes that succeeded (the run still reports every episode's outcome)")
    d.add_argument("--action", choices=("velocity", "position"), default=None,
                   help="what your controller's actions mean (default velocity; position: the target in metres)")
    d.add_argument("--backend", default="auto", help="auto, cpu or mjx-warp (default auto: the GPU batch if any)")
    d.add_argument("--batch", type=rows, default=None, help="episodes rolled out at once (default 1024 on MJX, "
                                                                "64 on cpu)")
    d.add_argument("--max-steps", type=steps, default=300, help="control steps before truncation (default 300)")
    success(d)
    d.add_argument("--out", type=folder, default=Path("outputs/demos"), help="the dataset's root (default outputs/demos)")
    d.add_argument("--replace", action="store_true", help=replace_help)
    d.add_argument("--share-out", action="store_true", help=share_help)
    d.add_argument("--no-progress", dest="progress", action="store_false")


def cmd_demos(args) -> int:
    from mjx_pusht.io.demos import write_demos
    from mjx_pusht.study.seeds import parse_seeds

    s = write_demos(args.controller, parse_seeds(args.seeds), args.out, backend=args.backend, batch=args.batch,
                    max_steps=args.max_steps, action=args.action, replace=args.replace, progress=args.progress,
                    successful_only=args.successful_only, share=args.share_out,
                    success_threshold=args.success_threshold, task=args.task)
    failed = s["failed_seeds"]
    print(f"{s['controller']}: {s['episodes']} episodes on {s['backend']} in {s['seconds']} s, success "
          f"{s['success_rate']:.1%}" + (f" (failed seeds: {', '.join(map(str, failed[:10]))}"
                                        f"{', ...' if len(failed) > 10 else ''})" if failed else ""))
    print(f"LeRobot dataset in {s['root']}: {s['written']} episodes, {s['frames']} frames"
          + (" (the successful ones)" if args.successful_only else ""))
    print(f"train on it: lerobot-train --dataset.repo_id=local/mjx_pusht_demos --dataset.root={s['root']} "
          "--policy.type=diffusion --policy.push_to_hub=false")
    return 0
