"""`mjx-pusht train`: check everything, train (DAgger: train/run.py; PPO: train/ppo.py), then judge the kept
policy with `evaluate` on the held-out seeds (out/eval) and print where everything went."""

from __future__ import annotations

import json
from pathlib import Path

from mjx_pusht.io.outputs import atomic_write_json, remove_own
from mjx_pusht.train.curve import kept as kept_row
from mjx_pusht.train.resume import TrainError
from mjx_pusht.train.summary import write_summary


# Each method's own settings and their defaults: given to the other method, a setting is refused, not ignored.
DAGGER_ONLY = {"fit_steps": 2000, "beta_decay": 0.7, "max_samples": 8_000_000, "teacher": "paced",
               "image_batch": None, "image_steps": None, "late_fits": None, "first_fits": None,
               "action_eps": None}
PPO_ONLY = {"timesteps": 50_000_000, "ppo_act": "sample", "lr_schedule": None, "minibatches": 32}
BOTH = {"max_grad_norm": 1.0, "envs": 4096, "eval_envs": 4096}  # both methods' settings, and defaults ('off' is None)
# DAgger on MuJoCo C (2 cores: a 4,096-episode iteration took 3.8 minutes, its held-out judgement 80 s): sized so
# `--minutes 1` learns something and ends in time (docs/training.md, "On a CPU"; notebook firsthour)
CPU_DAGGER = {"envs": 256, "eval_envs": 64, "fit_steps": 1000, "batch": 1024}
GENERAL = {"hidden": (256, 256, 256), "iterations": 10, "keep": "last"}  # either method's, on any backend
# DAgger from gym-pusht's image and agent_pos on MJX (a GPU): the recipe measured at 97.5% and 97.9% held-out on
# seeds 0 and 1 in 19.5 minutes, one H200 a run (docs/training.md, "From pixels on gym-pusht's task"): the state
# recipe's network, fits and episodes an iteration (16,384 and a 32 M ring: at 4,096 and 8 M the same runs levelled
# off at 96-97% with the fit's loss still falling), the image reader taught in 4,000 of each fit's 10,000 steps.
PIXELS_GYM_PUSHT = {"hidden": (1024, 1024, 1024), "fit_steps": 10_000, "batch": 4096, "beta_decay": 0.7,
                    "first_fits": 4, "iterations": 300, "minutes": 19.5, "image_steps": 4000, "image_batch": 512,
                    "envs": 16384, "max_samples": 32_000_000, "keep": "best"}


def recipe(args, backend: str) -> dict:
    """The defaults a run takes where its flags are not given, beyond each method's own: DAgger's sized for a CPU on
    MuJoCo C, or its recipe from gym-pusht's pixels on MJX."""
    from mjx_pusht.task.tasks import get as get_task

    if args.algo != "dagger":
        return GENERAL
    if backend == "cpu":
        return GENERAL | CPU_DAGGER
    if args.obs == "pixels_agent_pos" and get_task(args.task).name == "gym-pusht":
        return GENERAL | PIXELS_GYM_PUSHT
    return GENERAL


def _method_settings(args, backend: str) -> None:
    """Refuse the other method's settings in one line; fill this method's defaults (the parser leaves them None),
    DAgger's on cpu sized for a CPU and from gym-pusht's pixels on MJX its recipe (`recipe`)."""
    own, other = (PPO_ONLY, DAGGER_ONLY) if args.algo == "ppo" else (DAGGER_ONLY, PPO_ONLY)
    given = ["--" + k.replace("_", "-") for k in other if getattr(args, k) is not None]
    if given:
        method, theirs = ("PPO", "DAgger's") if args.algo == "ppo" else ("DAgger", "PPO's (--algo ppo)")
        raise TrainError(f"{', '.join(given)}: {theirs} setting{'s' if len(given) > 1 else ''}, not {method}'s")
    for k, default in (own | BOTH | recipe(args, backend)).items():
        if getattr(args, k) is None:
            setattr(args, k, default)
    if args.max_grad_norm == "off":
        args.max_grad_norm = None
    if args.algo == "dagger":  # the task's own unless given ('off': the plain squared error)
        from mjx_pusht.task.tasks import get as get_task

        eps = get_task(args.task).action_eps if args.action_eps is None else args.action_eps
        args.action_eps = None if eps == "off" else eps


def cmd_train(args) -> int:
    """`mjx-pusht train`: check everything, train, then judge the policy with `eval` on the held-out seeds."""
    from mjx_pusht.backends.base import resolve
    from mjx_pusht.io.banner import Banner
    from mjx_pusht.study.distributed import Processes
    from mjx_pusht.train.dagger import DaggerConfig

    from mjx_pusht.task.tasks import get as get_task

    processes = Processes(args.process_id, args.num_processes, args.coordinator, args.peer_timeout)
    if processes.many and args.resume:  # the processes other than 0 write into folders of their own (`_follow`)
        raise TrainError("--resume: not with --num-processes yet (training on several processes starts afresh)")
    if processes.many and args.algo == "ppo" and (args.minutes is not None or args.until is not None):
        # PPO stops from Brax's callbacks, which Brax calls on process 0 alone: the others would wait in the next
        # epoch's all-reduce for a process that left (DAgger's loop is ours: its processes agree on the stop)
        raise TrainError(f"{'--minutes' if args.minutes is not None else '--until'}: not with --algo ppo over "
                         "--num-processes (Brax's trainer calls back on process 0 alone, so only a whole "
                         "--timesteps ends every process together); give --timesteps")
    if processes.many and args.backend in ("cpu", "gym-pusht"):  # said now, not after every process has joined
        raise TrainError(f"--num-processes spreads training over the devices of the mjx-jax or mjx-warp backends, not "
                         f"{args.backend}")
    processes.initialize()  # before anything asks JAX for its devices
    task = get_task(args.task)
    if args.algo == "ppo" and args.goal != "fixed":
        raise TrainError("--goal random trains a goal-conditioned policy with DAgger; PPO trains on the fixed goal")
    if args.algo == "dagger" and args.teacher is None and task.name != "chapter":
        args.teacher = "expert"  # the paced teacher is the chapter expert's
    args.reset = task.check_reset(args.reset)
    name, why = resolve(args.backend)
    if name == "gym-pusht":  # found now, before the banner promises a run
        raise TrainError("train rolls out on cpu, mjx-jax or mjx-warp; gym-pusht itself judges a trained policy: "
                         "eval --task gym-pusht --backend gym-pusht --controller policy:PATH")
    _method_settings(args, name)
    from mjx_pusht.train.devices import check_divides, training_devices

    # PPO, as DAgger, on every local GPU unless asked (Brax's pmap; jax 0.11.2's compile of it segfaulted, lead12: the
    # pinned 0.10.2 trains, lead15, lead19). On MJX-Warp the env's staged graph modes keep ONE captured graph per call
    # site, whichever device calls it (warp/_src/jax/ffi.py; mujoco#3191), so Brax's second GPU replays the first's
    # and fails (WARP_STAGED, lead13), as XLA capturing (JAX) failed (lead15): on several GPUs PPO's env runs in
    # WARP (a graph per device: 96-100% on 2 and 4 H200s, lead19), and a MJX_PUSHT_ENV_GRAPH_MODE naming a mode that
    # failed is refused (train/ppo.py graph_mode).
    if args.algo == "ppo":
        from mjx_pusht.train.ppo import graph_mode

        graph_mode(name, args.devices)  # a graph mode that failed on several GPUs: one line, before anything is written
    devices = training_devices(args.devices, name)
    if args.algo == "ppo":
        check_divides(devices, envs=args.envs, batch=args.batch or 256)  # Brax gives each device its share of both
        return _cmd_ppo(args, name, why, devices, processes)
    cfg = DaggerConfig(obs_type=args.obs, envs=args.envs, iterations=args.iterations, hidden=tuple(args.hidden),
                       learning_rate=args.lr or 1e-3, batch=args.batch or 4096, fit_steps=args.fit_steps,
                       beta_decay=args.beta_decay, max_samples=args.max_samples, eval_envs=args.eval_envs,
                       seed=args.seed, reset=args.reset, teacher=args.teacher,
                       image_batch=args.image_batch or min(512, args.batch or 4096), image_steps=args.image_steps,
                       late_fits=args.late_fits, first_fits=args.first_fits, max_grad_norm=args.max_grad_norm,
                       action_eps=args.action_eps,
                       max_steps=args.max_steps, task=None if task.name == "chapter" else task.name,
                       success_threshold=args.success_threshold, goal=None if args.goal == "fixed" else args.goal,
                       randomize=args.randomize)
    if args.image_batch is not None and not cfg.image:  # as --image-steps: a state student has no image reader
        raise TrainError(f"--image-batch sizes a pixel student's image batches; a {cfg.obs_type} student has none")
    _fits_memory(cfg, name)
    check_divides(devices, envs=cfg.envs, eval_envs=cfg.eval_envs, batch=cfg.batch,
                  **({"image_batch": cfg.image_batch} if cfg.image else {}))  # each device's share of each
    if processes.many:  # one run: every process must have been given the same one
        from mjx_pusht.train.resume import config_dict

        processes.agree({**config_dict(cfg), "backend": name, "devices": len(devices), "out": str(args.out.resolve()),
                         **_folder_flags(args)})
        if not processes.leader:  # its files go to a folder of its own, removed after: process 0 writes the run's
            from mjx_pusht.train.run import train_dagger

            processes.settled("claim")  # process 0's claim of --out: its refusal ends this process too

            def follow(out: Path) -> None:  # DAgger's processes agree on their weights by construction (one mesh)
                train_dagger(cfg, name, out, minutes=args.minutes, progress=False, rerun=False, keep=args.keep,
                             devices=devices, until=args.until)

            return _follow(follow, devices, processes, args)
    out = processes.settled("claim", lambda: _claim(args))
    banner = Banner("train")
    print(f"backend: {name} ({why}); DAgger from {cfg.obs_type} on the {task.name} task: {cfg.envs} {cfg.reset} "
          f"episodes an iteration, "
          f"{cfg.iterations} iterations, held-out seeds {cfg.held_out_seeds()[0]}..{cfg.held_out_seeds()[-1]}"
          + ("; physics drawn per episode: " + ", ".join(f"{n} x{lo:g}..{hi:g}" for n, (lo, hi) in cfg.randomize)
             if cfg.randomize else ""))
    from mjx_pusht.train.run import train_dagger

    summary = train_dagger(cfg, name, out, resume=args.resume, minutes=args.minutes, progress=args.progress,
                           rerun=args.rerun, keep=args.keep, devices=devices, until=args.until)
    return _finish(args, name, out, summary, banner)


def _follow(train, devices: list, processes, args) -> int:
    """A process other than 0 of a run over several: `train(out)`, the same training on its own devices, its
    gradients averaged with every other's, its files (process 0 writes the run's) into a temporary folder, removed
    after. `train` returns a digest of the weights it ended with (PPO) or None."""
    import shutil
    import tempfile

    from mjx_pusht.train.devices import local_count

    out = Path(tempfile.mkdtemp(prefix=f"mjx-pusht-train-process-{processes.process_id}-"))
    try:
        digest = train(out)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    print(f"process {processes.process_id}: trained on {local_count(devices)} of the run's {len(devices)} devices"
          + (f" (its final weights' digest {digest}, as process 0's)" if digest else "")
          + f"; process 0 writes the run to {args.out}")
    return 0


def _folder_flags(args) -> dict:
    """The flags process 0 alone acts on (it claims, records and judges): compared between the processes like the
    run's settings, since one given to another process alone was ignored without a word (the fifteenth pass)."""
    return {k: getattr(args, k, None) for k in ("replace", "share_out", "rerun", "record")}


def _claim(args) -> Path:
    """The run's folder, claimed (its settings checked on --resume, before the run file: a refusal changes nothing),
    and rerun's presence checked."""
    from mjx_pusht.io.outputs import claim_out_dir

    out = claim_out_dir(args.out, "train", {}, replace=args.replace, share=args.share_out,
                        check=lambda path, same: _restart(path, args))
    _check_rerun(args)
    return out


def _restart(out: Path, args) -> None:
    """A folder holding a training run is continued (--resume) or started over (--replace), never mixed."""
    started = (out / "checkpoints" / "resume.msgpack").exists()
    if started and args.replace and not args.resume:
        remove_own(out / "checkpoints")
        print(f"--replace: removed the earlier training run's checkpoints in {out}")
    elif started and not args.resume:
        raise TrainError(f"--out {out} holds a training run: --resume to continue it, --replace to start over, "
                         "or give a new --out")


def _check_rerun(args) -> None:
    if args.rerun:  # found out now, not after the training it would otherwise end
        try:
            import rerun  # noqa: F401
        except ImportError:
            raise TrainError("train writes train.rrd and eval.rrd with rerun, which is not installed here: "
                             "pip install rerun-sdk, or pass --no-rerun") from None


def _cmd_ppo(args, name: str, why: str, devices: list, processes) -> int:
    """`train --algo ppo`: Brax's PPO (train/ppo.py), then the same judgement and files as DAgger's."""
    from mjx_pusht.io.banner import Banner

    if name == "cpu":
        raise TrainError("--algo ppo runs in Brax's jitted JAX: use --backend mjx-warp or mjx-jax "
                         "(cpu is MuJoCo C on the host)")
    from mjx_pusht.train.ppo import PPOConfig, train_ppo
    cfg = PPOConfig(obs_type=args.obs, envs=args.envs, timesteps=args.timesteps, evals=args.iterations,
                    hidden=tuple(args.hidden), learning_rate=args.lr or 3e-4, batch_size=args.batch or 256,
                    num_minibatches=args.minibatches,
                    eval_envs=args.eval_envs, seed=args.seed, reset=args.reset, act=args.ppo_act,
                    max_grad_norm=args.max_grad_norm, lr_schedule=args.lr_schedule, max_steps=args.max_steps,
                    success_threshold=args.success_threshold, randomize=args.randomize,
                    task=None if args.task == "chapter" else args.task)
    from mjx_pusht.train.devices import local_count

    run = dict(resume=args.resume, minutes=args.minutes, keep=args.keep, devices=local_count(devices), until=args.until)
    if processes.many:  # one run: every process must have been given the same one (Brax maps it over them all)
        from mjx_pusht.train.resume import config_dict

        processes.agree({**config_dict(cfg), "backend": name, "devices": len(devices), "out": str(args.out.resolve()),
                         **_folder_flags(args)})
        if not processes.leader:  # Brax's loop on its devices; process 0 alone judges and writes (Brax calls back there)
            processes.settled("claim")  # process 0's claim of --out: its refusal ends this process too
            return _follow(lambda out: train_ppo(cfg, name, out, progress=False, **run)[1], devices, processes, args)
    out = processes.settled("claim", lambda: _claim(args))
    banner = Banner("train")
    print(f"backend: {name} ({why}); Brax PPO from {cfg.obs_type} on the {cfg.the_task.name} task: {cfg.envs} envs, "
          f"{cfg.timesteps:,} env steps, held-out judgement {cfg.evals} times on seeds {cfg.held_out_seeds()[0]}..{cfg.held_out_seeds()[-1]}")
    curve, _ = train_ppo(cfg, name, out, progress=args.progress, **run)
    summary = write_summary(cfg, name, out, curve, args.rerun, method="ppo", kept=kept_row(curve, args.keep),
                            keep=args.keep, devices=len(devices))
    return _finish(args, name, out, summary, banner)


def _finish(args, name: str, out: Path, summary: dict, banner) -> int:
    import gc

    # Training's rollouts and renderers sit in reference cycles (jitted bound methods); collected during eval's CUDA
    # graph capture, their programs' unloading broke the capture ("operation not permitted when stream is
    # capturing", then Warp's render kernel failed: an H100 pixel run, notebook change 25). Collected here, before it.
    gc.collect()
    summary["eval"] = _judge(args, name, out, summary)
    ev = summary["eval"]
    lo, hi = ev["success_rate_ci95"]
    summary["held_out_success"], summary["held_out_success_ci95"] = ev["success_rate"], [lo, hi]
    atomic_write_json(out / "summary.json", summary)
    kept = summary.get("kept") or {}
    which = f"iteration {kept['iteration']}'s policy, kept by validation; " if kept.get("rule") == "best" else ""
    print(f"held-out success ({which}eval, {ev['n_episodes']} {summary['held_out']['reset']} seeds): "
          f"{ev['success_rate']:.1%} "
          f"(95% interval {lo:.1%}-{hi:.1%}); training wall-clock {summary['wall_seconds']:.0f} s "
          f"(simulation {summary['simulation_seconds']:.0f} s, learning {summary['learning_seconds']:.0f} s)")
    print(f"policy: {out / 'policy.msgpack'} (use it as --controller policy:{out / 'policy.msgpack'})\n"
          f"summary: {out / 'summary.json'}\ncurve: {out / 'curve.png'}")
    banner.done()
    return 0


def _judge(args, backend: str, out: Path, summary: dict) -> dict:
    """`evaluate` of policy:out/policy.msgpack on the held-out seeds, into out/eval (what `mjx-pusht eval
    --controller policy:out/policy.msgpack` writes)."""
    from mjx_pusht.study.evaluate import evaluate

    seeds = summary["held_out"]["seeds"]
    took = summary.pop("judgement_seconds", None)  # DAgger's last judgement of these seeds, in training
    print(f"judging {out / 'policy.msgpack'} with eval on the held-out seeds {seeds}"
          + (f": their episodes about {took:.0f} s, as the training's last judgement of them took, after eval's "
                 "start-up" if took is not None else ""))
    # this run's own judgement of the policy it just wrote: an earlier one (before --resume) judged another policy
    remove_own(out / "eval")
    evaluate(f"policy:{out / 'policy.msgpack'}", seeds, out / "eval", backend=backend,
             task=summary["held_out"].get("task", "chapter"), reset=summary["held_out"]["reset"],
             max_steps=summary["held_out"]["max_steps"], success_threshold=summary["held_out"]["success_coverage"],
             goal=summary["held_out"].get("goal", "fixed"), randomize=summary["held_out"].get("randomize"),
             record=args.record, progress=args.progress, rerun=args.rerun)
    s = json.loads((out / "eval" / "summary.json").read_text())
    return {k: s[k] for k in ("n_episodes", "n_success", "success_rate", "success_rate_ci95", "median_steps_to_success",
                              "n_non_finite", "n_rigid")} | {"backend": s["backend"], "seeds": seeds,
                                                             "table": "eval/per_episode.parquet"}


def _fits_memory(cfg, backend: str) -> None:
    """The run's largest allocations against this machine's memory, before anything is written (the documented
    maxima were MuJoCo's or XLA's out-of-memory tracebacks): the CPU worlds (boundary's measured bytes a world), and
    where JAX runs on this machine's CPU, the dataset's ring (float32 rows of the sample's width and a 3-wide label,
    as the learner allocates it) and the student's layers (weights, gradients, Adam's two moments: 4 float32s each)."""
    import jax

    from mjx_pusht.boundary import BYTES_PER_CPU_ENV, fits

    if backend == "cpu":
        fits(f"--envs {cfg.envs:,} on the cpu backend", cfg.envs, BYTES_PER_CPU_ENV, "fewer --envs", TrainError)
    if jax.default_backend() == "cpu":
        fits(f"--max-samples {cfg.max_samples:,}", cfg.max_samples, 4 * (cfg.sample_width + 3), "a smaller "
             "--max-samples", TrainError, measured=False)
        widths = [cfg.sample_width, *cfg.hidden, 2]
        fits(f"--hidden {','.join(map(str, cfg.hidden))}", sum(a * b + b for a, b in zip(widths, widths[1:])), 16,
             "narrower --hidden layers", TrainError, measured=False)
