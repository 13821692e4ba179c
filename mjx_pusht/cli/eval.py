"""`mjx-pusht eval`: the command line of `study.evaluate.evaluate` (a controller's episodes on many start
states): --param parsed (--randomize by its flag's type), Ctrl-C an exit status of 130."""

from __future__ import annotations


def cmd_eval(args) -> int:
    from mjx_pusht.cli.parser import UsageError
    from mjx_pusht.model.params import parse_params
    from mjx_pusht.study.evaluate import evaluate
    from mjx_pusht.study.seeds import parse_seeds

    if args.video is None:
        given = [f for f, v in (("--video-size", args.video_size), ("--video-episodes", args.video_episodes)) if v]
        if given:
            raise UsageError(f"{' and '.join(given)} only shape{'s' if len(given) == 1 else ''} --video's picture: give "
                             "--video FILE.gif with it, or leave it out")
    seeds = parse_seeds(args.seeds)
    params = parse_params(args.param)
    try:
        evaluate(args.controller, seeds, args.out, backend=args.backend, action=args.action, task=args.task,
                 reset=args.reset, success_threshold=args.success_threshold, goal=args.goal,
                 break_it=args.break_it, max_steps=args.max_steps, frame_skip=args.frame_skip, params=params,
                 randomize=args.randomize,
                 chunk=args.chunk, resume=args.resume, replace=args.replace, progress=args.progress,
                 record=args.record, rerun=args.rerun, video=args.video, video_episodes=args.video_episodes or 16,
                 video_size=args.video_size or 128, share=args.share_out)
    except KeyboardInterrupt:  # evaluate said where the finished chunks are
        return 130
    return 0
