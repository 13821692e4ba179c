"""`mjx-pusht train`: the loop around a method, and everything a run leaves behind.

    out/policy.msgpack          the latest policy (a controller: --controller policy:out/policy.msgpack)
    out/checkpoints/            one policy per iteration, and resume.msgpack (optimiser, dataset, curve)
    out/curve.csv, curve.png    held-out success after every iteration, by env steps and by wall-clock
    out/summary.json            method, obs, env steps, wall-clock (simulation / learning), device,
                                versions, the final held-out success with its 95% interval
    out/eval/                   `mjx-pusht eval --controller policy:...` on the held-out seeds: the
                                per-episode table, its summary and eval.rrd (a few episodes)
    out/train.rrd               the curve, as rerun scalars
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import threading
import time
from pathlib import Path

import numpy as np

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.io.outputs import atomic_write_bytes, atomic_write_json
from mjx_pusht.study.stats import wilson

CURVE_COLUMNS = ("iteration", "beta", "env_steps", "samples", "loss", "success", "success_lo", "success_hi",
                 "coverage", "sim_seconds", "learn_seconds", "wall_seconds", "pose_error_mm", "validation_success",
                 "validation_beta")


# The resume checkpoint holds the whole dataset (8 M samples: ~0.5 GB, ~4 s to write, measured on the H100
# run of notebook change 14), so it is written at most this often, and at the last iteration; a run killed
# between two repeats at most this much work on --resume (the per-iteration policies are written every time).
RESUME_EVERY_S = 60.0


class TrainError(MjxPushtError, ValueError):
    """A training run cannot start or resume as asked; the message says why."""


def _meta(cfg, iteration: int, env_steps: int, norm) -> dict:
    return {"obs_type": cfg.obs_type, "activation": cfg.activation, "in_mean": [float(v) for v in norm[0]],
            "in_std": [float(v) for v in norm[1]], "method": "dagger", "iteration": iteration,
            "env_steps": int(env_steps), "config": config_dict(cfg)} | ({"image": cfg.image} if cfg.image else {})


def config_dict(cfg) -> dict:
    """A method's config (DaggerConfig, PPOConfig) as JSON-ready values: what checkpoints and --resume compare."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(cfg).items()}


def train_dagger(cfg, backend: str, out: Path, *, resume: bool = False, minutes: float | None = None,
                 progress: bool = True, rerun: bool = True, keep: str = "last") -> dict:
    """Run DAgger on `backend` into `out`; returns the summary (also written as summary.json).

    `keep`: which fit is the run's policy.msgpack: the last one, or ("best") the one whose next rollout
    succeeded most on that iteration's fresh training seeds with the expert's share at most
    VALIDATION_BETA (`_kept`); never chosen by the held-out seeds, so its held-out rate is not a maximum
    taken over the curve's noise."""
    import jax
    from tqdm import tqdm

    from mjx_pusht.backends.base import has_gpu
    from mjx_pusht.backends.cpu import default_threads
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.task.episode import Episode
    from mjx_pusht.train.dagger import Learner, Rollouts
    from mjx_pusht.train.policy import save

    out = Path(out)
    ckpt = out / "checkpoints"
    ckpt.mkdir(parents=True, exist_ok=True)
    # A rollout is one long jitted scan, where MJX's default CUDA-graph mode ("WARP": graphs keyed on buffer
    # addresses, which stay put inside the scan) replays its captures; the env's own default, staged, is for
    # stepping once a call. Measured on an H100: 491k against 287k control steps/s at 4,096 (notebook change 16).
    graph_mode = "WARP" if backend == "mjx-warp" and has_gpu() else None
    env = PushTEnv(backend=backend, reset_kind=cfg.reset, episode=Episode(max_steps=cfg.max_steps),
                   threads=default_threads(), keep_states=False, pixels=cfg.image, graph_mode=graph_mode)
    rollouts, learner = Rollouts(env, cfg), Learner(cfg, env.images(cfg.image_batch) if cfg.image else None)
    curve, start, env_steps, wall0 = [], 0, 0, 0.0
    resume_path = ckpt / "resume.msgpack"
    if resume:
        start, env_steps, curve, wall0 = _restore(resume_path, cfg, learner)
    held_out = cfg.held_out_seeds()
    t_start = time.perf_counter() - wall0
    saved = time.perf_counter()
    bar = tqdm(desc="dagger", unit="iter", disable=not progress, initial=start, total=cfg.iterations)
    # Each fit's held-out judgement rides in the next iteration's rollout (the same policy drives both: the
    # held-out rows with beta 0, their samples never learned from), so judging costs a bigger batch, not a
    # second rollout (notebook change 16); the last fit, or the one that spends --minutes, is judged alone.
    pending = None  # (iteration, loss, learn seconds, sim seconds) of the fit awaiting its judgement
    writer = [None]  # the thread writing the resume checkpoint

    def judged(held, sim_judge: float, validation=None, validation_beta=None) -> bool:
        """Curve row, checkpoints and progress for the pending fit; True when --minutes is spent. `validation`:
        the training rows of the same rollout (fresh seeds, never held out), driven by this fit with the
        expert's share `validation_beta`."""
        nonlocal saved
        i, loss, learn, sim = pending
        k, n = int(held["success"].sum()), len(held_out)
        lo, hi = wilson(k, n)
        row = {"iteration": i, "beta": cfg.beta(i), "env_steps": env_steps, "samples": learner.filled,
               "loss": loss, "success": k / n, "success_lo": lo, "success_hi": hi,
               "coverage": float(held["coverage"].mean()), "sim_seconds": sim + sim_judge, "learn_seconds": learn,
               "wall_seconds": time.perf_counter() - t_start,
               "pose_error_mm": learner.pose_error_mm,  # a pixel student's reading of the T, in its last fit
               "validation_success": None if validation is None else float(np.mean(validation["success"])),
               "validation_beta": validation_beta}
        curve.append(row)
        meta = _meta(cfg, i, env_steps, learner.norm)
        save(ckpt / f"policy_{i:03d}.msgpack", learner.params, meta)
        save(out / "policy.msgpack", learner.params, meta)
        stop = minutes is not None and row["wall_seconds"] > 60 * minutes
        if stop or i == cfg.iterations - 1 or time.perf_counter() - saved > RESUME_EVERY_S:
            writer[0] = _checkpoint(resume_path, cfg, learner, i, env_steps, curve, writer[0])
            saved = time.perf_counter()
        bar.set_postfix(success=f"{k / n:.1%}", loss=f"{loss:.4f}", steps=env_steps,
                        **({"pose_mm": f"{learner.pose_error_mm:.2f}"} if cfg.image else {}))
        bar.update(1)
        return stop

    # On MJX every rollout has the held-out rows, so the scan compiles for one batch shape: the first
    # iteration's show the untrained student, unrecorded (a second shape cost ~8 s of a 5-minute budget,
    # notebook change 23); on cpu, nothing to compile, they are rolled only when there is a fit to judge.
    one_shape = backend != "cpu"
    for i in range(start, cfg.iterations):
        seeds, beta = cfg.train_seeds(i), np.full(cfg.envs, cfg.beta(i), np.float32)
        if pending is not None or one_shape:  # the last fit's judgement, in the same batch
            seeds, beta = np.concatenate([seeds, held_out]), np.concatenate([beta, np.zeros(len(held_out), np.float32)])
        (x, y, outcome), sim = _timed(rollouts, learner.params, learner.norm or _unit(cfg), seeds, beta, i, cfg.envs)
        if pending is not None:
            stop = judged({k: v[cfg.envs:] for k, v in outcome.items()}, 0.0,
                          {k: v[:cfg.envs] for k, v in outcome.items()}, float(cfg.beta(i)))
            pending = None
            if stop:
                curve[-1]["sim_seconds"] += sim  # spent, though the samples go unlearned: the judged policy is the run's
                break
        env_steps += len(x)
        learner.add(x, y, keep=i == 0)
        loss, learn = _timed(learner.fit, i)
        pending = (i, loss, learn, sim)
        if minutes is not None and time.perf_counter() - t_start > 60 * minutes:
            break  # judged alone below: no rollout past the budget
    if pending is not None:
        seeds, n_train = held_out, 0
        if one_shape:  # the same shape again: training seeds ride along, their samples not learned
            seeds, n_train = np.concatenate([cfg.train_seeds(pending[0] + 1), held_out]), cfg.envs
        (_, _, held), sim_judge = _timed(rollouts, learner.params, learner.norm, seeds, 0.0, cfg.iterations + pending[0],
                                         0)
        judged({k: v[n_train:] for k, v in held.items()}, sim_judge,
               {k: v[:n_train] for k, v in held.items()} if n_train else None, 0.0 if n_train else None)
    if writer[0] is not None:
        writer[0].join()
    if curve and curve[-1]["iteration"] < cfg.iterations - 1:
        bar.write(f"stopping after iteration {curve[-1]['iteration']}: the {minutes:g}-minute budget is spent")
    bar.close()
    jax.block_until_ready(learner.params)
    kept = _kept(curve, keep)
    if kept is not None and kept["iteration"] != curve[-1]["iteration"]:
        shutil.copyfile(ckpt / f"policy_{kept['iteration']:03d}.msgpack", out / "policy.msgpack")
        bar.write(f"keeping iteration {kept['iteration']}'s policy: {kept['validation_success']:.1%} on its "
                  f"validation rollout (held-out {kept['success']:.1%})")
    return _summary(cfg, backend, out, curve, rerun, kept=kept, keep=keep)


VALIDATION_BETA = 0.01  # --keep best: a fit's validation rollout counts once the expert acts this little in it


def _validated(row: dict) -> bool:
    """Whether a curve row's validation rollout counts: there was one, and the expert acted in at most
    VALIDATION_BETA of it (rows written before validation was recorded have neither key)."""
    beta = row.get("validation_beta")
    return row.get("validation_success") is not None and beta is not None and beta <= VALIDATION_BETA


def _kept(curve: list[dict], keep: str) -> dict | None:
    """The curve row of the fit --keep names: the last, or the best by validation success among the fits
    `_validated` (the last when none is)."""
    if not curve:
        return None
    rows = [r for r in curve if _validated(r)]
    if keep == "last" or not rows:
        return curve[-1]
    return max(reversed(rows), key=lambda r: r["validation_success"])  # a tie: the later fit


def _unit(cfg):
    from mjx_pusht.train.policy import feature_size

    w = feature_size(cfg.obs_type)
    return np.zeros(w, np.float32), np.ones(w, np.float32)


def _timed(fn, *args):
    import jax

    t0 = time.perf_counter()
    result = jax.block_until_ready(fn(*args))
    return result, time.perf_counter() - t0


def _checkpoint(path, cfg, learner, iteration, env_steps, curve, writer=None):
    """Everything --resume needs (optimiser, dataset ring, normalisation, curve), written whole. The arrays are
    copied to the host here; encoding and writing (~4 s for 8 M samples on the H100 run of notebook change 14) go
    on in a thread while training continues. Returns that thread: join it before the next one, and at the end."""
    from flax import serialization

    from mjx_pusht.train.policy import to_numpy

    if writer is not None:
        writer.join()  # one file, written in order
    tree = {"config": json.dumps(config_dict(cfg), sort_keys=True), "iteration": iteration, "env_steps": env_steps,
            "curve": json.dumps(curve), "params": to_numpy(learner.params),
            "opt_state": serialization.to_state_dict(to_numpy(learner.opt_state)),
            "x": np.asarray(learner.x[:learner.filled]), "y": np.asarray(learner.y[:learner.filled]),
            "head": learner.head, "floor": learner.floor, "norm_mean": learner.norm[0], "norm_std": learner.norm[1]}
    writer = _Writer(lambda: atomic_write_bytes(path, serialization.msgpack_serialize(tree)))
    writer.start()
    return writer


class _Writer(threading.Thread):
    """A thread whose failure (a full disk) is raised in the training loop when joined, not only printed."""

    def __init__(self, write):
        super().__init__(name="resume-checkpoint")
        self.write, self.error = write, None

    def run(self) -> None:
        try:
            self.write()
        except BaseException as e:  # noqa: BLE001 - handed to the joining thread as it is
            self.error = e

    def join(self, timeout=None) -> None:
        super().join(timeout)
        if self.error is not None:
            raise self.error


def resume_tree(path: Path, cfg, may_change: tuple[str, ...]) -> dict:
    """The resume checkpoint at `path` (either method's), refused in one line if it is missing, unreadable,
    or from a run with other settings than `cfg` (those in `may_change`, how far to go, excepted)."""
    from flax import serialization

    if not path.is_file():
        raise TrainError(f"--resume: {path} does not exist; nothing to resume (run without --resume to start)")
    try:
        tree = serialization.msgpack_restore(path.read_bytes())
        saved = json.loads(tree["config"])
    except Exception as e:  # noqa: BLE001 - any decoding failure means the same thing to the user
        raise TrainError(f"--resume: {path} is unreadable ({type(e).__name__}); start again without --resume") from None
    now = config_dict(cfg)
    # both keys' sides: another method's run differs in the names of its settings too
    diff = sorted(k for k in set(saved) | set(now) if saved.get(k) != now.get(k) and k not in may_change)
    if diff:
        raise TrainError(f"--resume: the run in {path.parent.parent} was started with other settings "
                         f"({', '.join(diff[:6])}); give the same ones, or a new --out")
    return tree


def _restore(path, cfg, learner):
    import jax
    import jax.numpy as jnp
    from flax import serialization

    tree = resume_tree(path, cfg, ("iterations",))
    try:  # the optimiser's layout is this version's: one Adam a part of the network (dagger._parts)
        learner.opt_state = serialization.from_state_dict(learner.opt_state, tree["opt_state"])
    except (KeyError, ValueError, TypeError) as e:
        raise TrainError(f"--resume: {path} holds an optimiser state this version does not use ({type(e).__name__}; "
                         "written before the fit's parts had an Adam each?); start again without --resume") from None
    learner.params = jax.tree.map(jnp.asarray, tree["params"])
    n = len(tree["x"])
    learner.x = learner.x.at[:n].set(jnp.asarray(tree["x"]))
    learner.y = learner.y.at[:n].set(jnp.asarray(tree["y"]))
    learner.filled, learner.head, learner.floor = n, int(tree["head"]), int(tree["floor"])
    learner.norm = (np.asarray(tree["norm_mean"]), np.asarray(tree["norm_std"]))
    curve = json.loads(tree["curve"])
    return int(tree["iteration"]) + 1, int(tree["env_steps"]), curve, curve[-1]["wall_seconds"] if curve else 0.0


def _summary(cfg, backend, out: Path, curve, rerun: bool = True, method: str = "dagger", kept: dict | None = None,
             keep: str = "last") -> dict:
    from mjx_pusht.backends.base import versions

    last = curve[-1] if curve else None
    final = kept or last
    summary = {
        "method": method, "obs_type": cfg.obs_type, "backend": backend, "device": _device(backend),
        "versions": versions(), "config": config_dict(cfg), "iterations_run": len(curve),
        "env_steps": last["env_steps"] if last else 0,
        "wall_seconds": round(last["wall_seconds"], 3) if last else 0.0,
        "simulation_seconds": round(sum(r["sim_seconds"] for r in curve), 3),
        "learning_seconds": round(sum(r["learn_seconds"] for r in curve), 3),
        "held_out": {"seeds": f"{cfg.held_out_seeds()[0]}:{cfg.held_out_seeds()[-1] + 1}", "reset": cfg.reset,
                     "success_coverage": 0.95, "max_steps": cfg.max_steps},
        "final_success": final["success"] if final else None,
        "final_success_ci95": [final["success_lo"], final["success_hi"]] if final else None,
        "kept": {"rule": keep, "iteration": final["iteration"], "validation_success": final.get("validation_success"),
                 "validation_beta": final.get("validation_beta")} if final else None,
        "policy": "policy.msgpack",  # paths in a summary are relative to its folder, never the machine's
        "curve": curve,
    }
    if method == "ppo":
        summary["wall_clock_note"] = ("simulation_seconds is the held-out judging; learning_seconds is Brax's training "
                                      "epochs, whose rollouts (simulation) and updates run in one program")
    title = {"dagger": "DAgger", "ppo": "Brax PPO"}[method]
    write_curve(out, curve, f"{title} from {cfg.obs_type}, {backend} on {summary['device']}", rerun)
    atomic_write_json(out / "summary.json", summary)
    return summary


def _device(backend: str) -> str:
    if backend == "cpu":
        import os

        return f"cpu ({os.cpu_count()} cores)"
    import jax

    return str(jax.devices()[0].device_kind)


def write_curve(out: Path, curve: list[dict], title: str, rerun: bool = True) -> None:
    """curve.csv, curve.png (held-out success with its 95% band, by env steps and by wall-clock), train.rrd."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = [",".join(CURVE_COLUMNS)] + [",".join(f"{r[c]:.6g}" if isinstance(r.get(c), float) else
                                                  "" if r.get(c) is None else str(r[c])
                                                  for c in CURVE_COLUMNS) for r in curve]
    atomic_write_bytes(out / "curve.csv", ("\n".join(lines) + "\n").encode())
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, key, label in ((axes[0], "env_steps", "env control steps (millions)"),
                           (axes[1], "wall_seconds", "training wall-clock (minutes)")):
        scale = 1e6 if key == "env_steps" else 60.0
        xs = np.array([r[key] for r in curve]) / scale
        ax.fill_between(xs, [100 * r["success_lo"] for r in curve], [100 * r["success_hi"] for r in curve], alpha=0.3)
        ax.plot(xs, [100 * r["success"] for r in curve], "o-", label="held-out success")
        val = [(x, 100 * r["validation_success"]) for x, r in zip(xs, curve) if _validated(r)]
        if val:  # what --keep best chooses by: the next rollout's fresh training seeds
            ax.plot(*zip(*val), ".--", alpha=0.6, label="validation (training seeds, expert share <= 1%)")
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success, % (coverage >= 0.95 in 300 steps)")
    axes[0].set_ylim(0, 100)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(out / "curve.png", buf.getvalue())
    if rerun:
        _record_curve(out / "train.rrd", curve)


def _record_curve(path: Path, curve: list[dict]) -> None:
    import rerun as rr

    rec = rr.RecordingStream("mjx_pusht_train")
    tmp = path.with_name(f".{path.name}.tmp")  # written whole, then renamed: never a half recording
    rec.save(str(tmp))
    for r in curve:
        rec.set_time("env_steps", sequence=int(r["env_steps"]))
        rec.log("curve/held_out_success", rr.Scalars(r["success"]))
        rec.log("curve/held_out_coverage", rr.Scalars(r["coverage"]))
        if r["loss"] is not None:  # PPO's curve has no fit loss of ours
            rec.log("curve/loss", rr.Scalars(r["loss"]))
    rec.flush()
    rec.disconnect()
    tmp.replace(path)


def cmd_train(args) -> int:
    """`mjx-pusht train`: check everything, train, then judge the policy with `eval` on the held-out seeds."""
    from mjx_pusht.backends.base import resolve
    from mjx_pusht.cli.banner import Banner
    from mjx_pusht.io.outputs import claim_out_dir
    from mjx_pusht.train.dagger import DaggerConfig

    name, why = resolve(args.backend)
    if args.algo == "ppo":
        return _cmd_ppo(args, name, why)
    cfg = DaggerConfig(obs_type=args.obs, envs=args.envs, iterations=args.iterations, hidden=tuple(args.hidden),
                       learning_rate=args.lr or 1e-3, batch=args.batch or 4096, fit_steps=args.fit_steps,
                       beta_decay=args.beta_decay, max_samples=args.max_samples, eval_envs=args.eval_envs,
                       seed=args.seed, reset=args.reset, teacher=args.teacher,
                       image_batch=args.image_batch or min(512, args.batch or 4096), image_steps=args.image_steps)
    out = claim_out_dir(args.out, "train", {}, replace=args.replace)  # the run's settings: checked on --resume
    _restart(out, args)
    _check_rerun(args)
    banner = Banner("train")
    print(f"backend: {name} ({why}); DAgger from {cfg.obs_type}: {cfg.envs} {cfg.reset} episodes an iteration, "
          f"{cfg.iterations} iterations, held-out seeds {cfg.held_out_seeds()[0]}..{cfg.held_out_seeds()[-1]}")
    summary = train_dagger(cfg, name, out, resume=args.resume, minutes=args.minutes, progress=args.progress,
                           rerun=args.rerun, keep=args.keep)
    return _finish(args, name, out, summary, banner)


def _restart(out: Path, args) -> None:
    """A folder holding a training run is continued (--resume) or started over (--replace), never mixed."""
    started = (out / "checkpoints" / "resume.msgpack").exists()
    if started and args.replace and not args.resume:
        shutil.rmtree(out / "checkpoints")
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


def _cmd_ppo(args, name: str, why: str) -> int:
    """`train --algo ppo`: Brax's PPO (train/ppo.py), then the same judgement and files as DAgger's."""
    if args.keep != "last":
        raise TrainError("--keep best is DAgger's (a fit judged on its next rollout's fresh seeds); PPO keeps its last")
    from mjx_pusht.cli.banner import Banner
    from mjx_pusht.io.outputs import claim_out_dir

    if name == "cpu":
        raise TrainError("--algo ppo runs in Brax's jitted JAX: use --backend mjx-warp or mjx-jax "
                         "(cpu is MuJoCo C on the host)")
    try:
        from mjx_pusht.train.ppo import PPOConfig, train_ppo
    except ImportError as e:
        raise TrainError(f"--algo ppo needs Brax ({e.name} is missing): pip install 'mjx-pusht[train]'") from None
    cfg = PPOConfig(obs_type=args.obs, envs=args.envs, timesteps=args.timesteps, evals=args.iterations,
                    hidden=tuple(args.hidden), learning_rate=args.lr or 3e-4, batch_size=args.batch or 256,
                    eval_envs=args.eval_envs, seed=args.seed, reset=args.reset)
    out = claim_out_dir(args.out, "train", {}, replace=args.replace)
    _restart(out, args)
    _check_rerun(args)
    banner = Banner("train")
    print(f"backend: {name} ({why}); Brax PPO from {cfg.obs_type}: {cfg.envs} envs, {cfg.timesteps:,} env steps, "
          f"held-out judgement {cfg.evals} times on seeds {cfg.held_out_seeds()[0]}..{cfg.held_out_seeds()[-1]}")
    curve = train_ppo(cfg, name, out, resume=args.resume, progress=args.progress, minutes=args.minutes)
    summary = _summary(cfg, name, out, curve, args.rerun, method="ppo")
    return _finish(args, name, out, summary, banner)


def _finish(args, name: str, out: Path, summary: dict, banner) -> int:
    import gc

    # Training's rollouts and renderers sit in reference cycles (jitted bound methods); collected during eval's CUDA
    # graph capture, their programs' unloading broke the capture ("operation not permitted when stream is
    # capturing", then Warp's render kernel failed: an H100 pixel run, notebook change 25). Collected here, before it.
    gc.collect()
    summary["eval"] = _judge(args, name, out, summary)
    atomic_write_json(out / "summary.json", summary)
    ev = summary["eval"]
    lo, hi = ev["success_rate_ci95"]
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
    """`mjx-pusht eval --controller policy:out/policy.msgpack` on the held-out seeds, into out/eval."""
    from mjx_pusht.cli.commands import cmd_eval
    from mjx_pusht.cli.parser import build_parser

    seeds = summary["held_out"]["seeds"]
    # this run's own judgement of the policy it just wrote: an earlier one (before --resume) judged another policy
    shutil.rmtree(out / "eval", ignore_errors=True)
    argv = ["eval", "--controller", f"policy:{out / 'policy.msgpack'}", "--seeds", seeds, "--backend", backend,
            "--reset", summary["held_out"]["reset"], "--out", str(out / "eval"), "--record", str(args.record), "--max-steps", str(summary["held_out"]["max_steps"])]
    argv += [] if args.progress else ["--no-progress"]
    argv += [] if args.rerun else ["--no-rerun"]
    ev = build_parser().parse_args(argv)
    cmd_eval(ev)
    s = json.loads((out / "eval" / "summary.json").read_text())
    return {k: s[k] for k in ("n_episodes", "n_success", "success_rate", "success_rate_ci95", "median_steps_to_success",
                              "n_non_finite", "n_rigid")} | {"backend": s["backend"], "seeds": seeds,
                                                             "table": "eval/per_episode.parquet"}
