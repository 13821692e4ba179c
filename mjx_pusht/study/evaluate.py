"""`evaluate`: a controller's episodes on many start states, into a folder: per_episode.parquet, the success
rate with its 95% interval (summary.json), eval.rrd (a few episodes) and an optional video. What
`mjx-pusht eval` runs, and what `mjx-pusht train` judges its policy with on the held-out seeds."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def evaluate(controller: str, seeds, out, *, backend: str = "auto", action: str | None = None, task: str = "chapter",
             reset: str | None = None, success_threshold: float | None = None, goal: str = "fixed",
             break_it: str = "none", max_steps: int = 300, frame_skip: int = 10, params=(), randomize=None,
             chunk: int | None = None,
             resume: bool = False, replace: bool = False, progress: bool = True, record: int = 4, rerun: bool = True,
             video: Path | None = None, video_episodes: int = 16, video_size: int = 128, share: bool = False) -> dict:
    """Run `controller` (a `task.controllers.load` spec: `expert`, `policy:PATH`, ...) for an episode from each
    seed's start state (`seeds`: an array, or a spec such as "512" or "A:B") on `backend`, into `out`; returns
    the summary (also written as summary.json). `task`: task/tasks.TASKS (`expert` is its expert; `reset` None:
    its default starts; `success_threshold` None: its own success coverage; `goal`: "fixed", or "random", a goal
    per episode from its seed, toward which a controller of the fixed goal acts from the goal's frame). `params`:
    (name, values) pairs swept as a grid. `randomize`: {name: (lo, hi)} scale factors drawn per episode from its
    seed (model/randomize.py); the drawn values are the table's param_ columns.

    Bad input (a controller that cannot load, a video name without an encoder) fails before anything is
    written. Interrupted, the finished chunks stay in `out` (finished with `resume=True`) and the
    KeyboardInterrupt goes on up."""
    from mjx_pusht.backends.base import resolve, versions
    from mjx_pusht.backends.cpu import default_threads
    from mjx_pusht.io.outputs import atomic_write_json
    from mjx_pusht.io.record import record_episodes
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.study.batch import record as record_rows
    from mjx_pusht.study.batch import start_batch, warn_mujoco
    from mjx_pusht.study.seeds import parse_seeds
    from mjx_pusht.study.stats import steps_text, summarize_episodes
    from mjx_pusht.study.sweep import finish, kept_chunks, run_sweep
    from mjx_pusht.task.controllers import describe
    from mjx_pusht.task.tasks import get as get_task

    seeds = parse_seeds(seeds) if isinstance(seeds, str) else np.asarray(seeds, dtype=np.int64)
    params = tuple((n, tuple(v)) for n, v in params)
    the_task = get_task(task)
    reset = the_task.check_reset(reset)
    episode = the_task.episode(max_steps, frame_skip, success_threshold, goal)
    spec, controller = controller, the_task.controller(controller, action=action, frame_skip=frame_skip, goal=goal)
    if video is not None:
        from mjx_pusht.io.video import check_grid, check_path

        check_path(video, replace, out)  # a bad name, a missing encoder or a size too large fails now, not after the episodes
        check_grid(video_size, min(video_episodes, len(seeds)), max_steps)
    name, why = resolve(backend)
    if video is not None:  # a GL that cannot draw the video: refused now, not once the results are written
        from mjx_pusht.model.scene import build_model
        from mjx_pusht.render.pixels import probe_gl

        probe_gl(build_model(the_task.scene(break_it)))
    config = {"command": "eval", "backend": name, "controller": spec, "action": controller.action_type,
              "task": task, "reset": reset, "success_threshold": episode.success, "goal": goal, "break_it": break_it, "max_steps": max_steps,
              "frame_skip": frame_skip, "params": [[n, list(v)] for n, v in params],
              "controller_sha256": policy_sha256(spec)}
    scenario = Scenario(the_task.scene(break_it), params=params, reset=reset, controller=controller, episode=episode,
                        randomize=randomize)
    if scenario.randomize:  # an unrandomised run's config (and so its fingerprint) stays as it was
        config["randomize"] = [[n, list(r)] for n, r in scenario.randomize]
    reads = [spec.removeprefix("policy:")] if spec.startswith("policy:") else []  # never replaced by this run
    from mjx_pusht.io.video import earlier, stamp

    here = earlier(out)  # the video an earlier eval drew in this --out: its own, set aside with it by --replace
    row_seeds, combos, out, banner, clock, backend = start_batch("eval", out, seeds, name, why, config, scenario,
                                                                 replace=replace, resume=resume, reads=reads,
                                                                 share=share, writes=[video] if video else [],
                                                                 earlier=[*here, *earlier(out, aside=True)])
    print(f"controller: {describe(controller)}; task: {task}; reset: {reset}; {len(seeds)} episodes of at most "
          f"{max_steps} control steps x {frame_skip} physics steps; device: {backend.device}; "
          f"pusher shape: {backend.pusher}")
    # small chunks on the CPU keep the progress bar (and --resume) fine-grained
    chunk = chunk or (128 * default_threads() if name == "cpu" else None)
    try:
        run = run_sweep(backend, row_seeds, out, config=config, chunk=chunk, resume=resume,
                        progress=progress, combos=combos, episodes=True)
    except KeyboardInterrupt:
        print(f"\ninterrupted: {kept_chunks(out)}", file=sys.stderr)
        raise
    finally:
        backend.close()
    clock.lap("episodes")
    r = run.rollouts
    summary = {"config": config, **backend.describe(), "versions": versions(), "controller": describe(controller),
               "success_coverage": episode.success, **summarize_episodes(r),
               "compile_seconds": round(run.compile_seconds, 3), "run_seconds": round(run.run_seconds, 3)}
    finish(out, run, name="per_episode.parquet", episodes=True)
    clock.lap("table_writing")
    summary["timing"] = clock.report(run.timing)
    if video is None and here and here[0].is_file():  # kept in place: this run's results are the same seeds and
        summary["video"] = stamp(here[0])  # settings' (other ones' --replace set the video aside)
    atomic_write_json(out / "summary.json", summary)
    lo, hi = summary["success_rate_ci95"]
    print(f"success: {summary['n_success']} of {summary['n_finite']} episodes ({summary['success_rate']:.1%}, "
          f"95% interval {lo:.1%}-{hi:.1%}); median steps to success {steps_text(summary['median_steps_to_success'])}; "
          f"median final coverage {summary['final_coverage'].get('median', float('nan')):.3f}")
    warn_mujoco(summary, "episodes")
    if summary["n_non_finite"]:
        print(f"WARNING: {summary['n_non_finite']} episodes went non-finite (flagged, left out of the rate): "
              f"{summary['non_finite_seeds'][:10]}")
    if summary["n_escaped"] and break_it != "free-tee":
        print(f"WARNING: {summary['n_escaped']} episodes left the walled workspace (the T or the pusher): "
              f"{summary['escaped_seeds'][:10]}")
    if break_it == "none" and summary["n_rigid"] + summary["n_mujoco_warnings"] != len(r):
        print(f"WARNING: the welded T came apart in {len(r) - summary['n_rigid'] - summary['n_mujoco_warnings']} episodes")
    print(f"table: {out / 'per_episode.parquet'}\nsummary: {out / 'summary.json'}")
    try:
        record_rows(out / "eval.rrd", "episodes", backend, r, combos, lambda: np.arange(min(record, len(r))),
                    record_episodes, summary, clock, rerun=rerun, n=record)
        if video is not None:
            _video(video, video_episodes, video_size, out, backend, r, combos, episode, summary, clock)
    except KeyboardInterrupt:  # the caller's exit status says 130; this line says what is kept (it said nothing)
        print(f"\ninterrupted: the table and summary in {out} are whole; the recording or video was not finished "
              "(each is written whole or not at all): rerun to draw it", file=sys.stderr)
        raise
    banner.done()
    return summary


def policy_sha256(spec: str) -> str | None:
    """A trained policy's file, by content: what `compare --evals` checks before it pairs two evals' rows
    (the same path on two machines can hold other weights). None for the built-in controllers."""
    if not spec.startswith("policy:"):
        return None
    import hashlib

    return hashlib.sha256(Path(spec.removeprefix("policy:")).read_bytes()).hexdigest()


def _video(path: Path, n: int, size: int, out: Path, backend, r, combos, episode, summary: dict, clock) -> None:
    """The first `n` episodes rerun with a trace and drawn as a grid of `size`-pixel tiles (video.py)."""
    from mjx_pusht.io.outputs import atomic_write_json
    from mjx_pusht.io.video import episode_grid, stamp, write
    from mjx_pusht.model.layout import QposLayout

    shown = np.arange(min(n, len(r)))
    traced = backend.run(r.seeds[shown], trace=True, combos=combos[shown])
    # the video ends a second after the last shown episode does
    last = min(int(np.max(traced.episode["length"])) + 10, episode.max_steps)
    goals = None
    if episode.goal is not None:  # each episode's random goal, drawn from its seed as its rollout drew it
        from mjx_pusht.task.controllers import seed_key
        from mjx_pusht.task.goals import draw

        goals = draw(seed_key(r.seeds[shown]), episode.goal, np.float64)
    frames = episode_grid(backend.model, traced.trace.qpos[:, : last * episode.frame_skip + 1],
                          QposLayout.of(backend.model), r.seeds[shown], episode.frame_skip, episode.success, size,
                          goals)
    fps = 1 / (episode.frame_skip * traced.trace.dt)
    write(path, frames, fps)
    summary["timing"]["video"] = round(clock.lap("video"), 3)
    summary["video"] = stamp(path)  # what a later --replace may overwrite: this very file, and no other
    atomic_write_json(Path(out) / "summary.json", summary)
    print(f"video: {path} ({len(shown)} episodes, {len(frames)} frames at {fps:g} per second)")
