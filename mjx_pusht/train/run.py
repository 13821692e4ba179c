"""`train_dagger`: a DAgger training run, its loop and everything it leaves behind (`mjx-pusht train` runs it).

    out/policy.msgpack          the latest policy (a controller: --controller policy:out/policy.msgpack)
    out/checkpoints/            one policy per iteration, and resume.msgpack (optimiser, curve) with its dataset ring
                                (resume-ring-NNNNNN.f32, the iteration it was written after)
    out/curve.csv, curve.png    held-out success after every iteration, by env steps and by wall-clock
    out/summary.json            method, obs, env steps, wall-clock (simulation / learning), device,
                                versions, the final held-out success with its 95% interval
    out/eval/                   (`mjx-pusht train`, after the run) `evaluate` of policy:out/policy.msgpack on
                                the held-out seeds: the per-episode table, its summary and eval.rrd
    out/train.rrd               the curve, as rerun scalars
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np

from mjx_pusht.errors import needs
from mjx_pusht.study.stats import wilson
from mjx_pusht.task.memory import CHAPTER
from mjx_pusht.train.curve import kept as kept_fit
from mjx_pusht.train.curve import reached
from mjx_pusht.train.resume import TrainError, checkpoint, config_dict, restore, resume_every_s
from mjx_pusht.train.summary import write_summary


def _meta(cfg, iteration: int, env_steps: int, norm) -> dict:
    return {"obs_type": cfg.obs_type, "activation": cfg.activation, "in_mean": [float(v) for v in norm[0]],
            "in_std": [float(v) for v in norm[1]], "method": "dagger", "iteration": iteration,
            "env_steps": int(env_steps), "config": config_dict(cfg)} | ({"image": cfg.image} if cfg.image else {}) | (
        {"memory": cfg.memory.meta()} if cfg.memory != CHAPTER else {}) | ({"goal": True} if cfg.goal_conditioned else {})


def train_dagger(cfg, backend: str, out: Path, *, resume: bool = False, minutes: float | None = None,
                 progress: bool = True, rerun: bool = True, keep: str = "last", devices=None,
                 until: float | None = None) -> dict:
    """Run DAgger on `backend` into `out`; returns the summary (also written as summary.json).

    `keep`: which fit is the run's policy.msgpack: the last one, or ("best") the one whose next rollout
    succeeded most on that iteration's fresh training seeds with the expert's share at most
    VALIDATION_BETA (`curve.kept`); never chosen by the held-out seeds, so its held-out rate is not a maximum
    taken over the curve's noise. `minutes`: the budget of the training and its last judgement (`Budget`).
    `devices`: those the rollouts and the learner spread over (devices.py; None: JAX's default device). `until`: stop
    at the first held-out judgement at or above this success rate (its samples are not learned from)."""
    needs("train_dagger", "train", ("flax", "optax"))  # one line naming the extra, before any work
    import jax
    from tqdm import tqdm

    from mjx_pusht.train.dagger import Rollouts
    from mjx_pusht.train.devices import Spread
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.policy import save

    out = Path(out)
    ckpt = out / "checkpoints"
    ckpt.mkdir(parents=True, exist_ok=True)
    env = dagger_env(cfg, backend)
    spread = Spread(devices or jax.devices()[:1])
    rollouts = Rollouts(env, cfg, spread)
    learner = Learner(cfg, env.images(cfg.image_batch // len(spread)) if cfg.image else None, spread)
    curve, start, env_steps, wall0 = [], 0, 0, 0.0
    resume_path = ckpt / "resume.msgpack"
    if resume:
        start, env_steps, curve, wall0 = restore(resume_path, cfg, learner)
        learner.place()
    held_out = cfg.held_out_seeds()
    t_start = time.perf_counter() - wall0
    saved, every = time.perf_counter(), resume_every_s(learner.x.nbytes + learner.y.nbytes)
    bar = tqdm(desc="dagger", unit="iter", disable=not progress, initial=start, total=cfg.iterations)
    # Each fit's held-out judgement rides in the next iteration's rollout (the same policy drives both: the
    # held-out rows with beta 0, their samples never learned from), so judging costs a bigger batch, not a
    # second rollout (notebook change 16); the last fit, or the last that --minutes leaves time for, is judged alone.
    pending = None  # (iteration, loss, learn seconds, sim seconds) of the fit awaiting its judgement
    writer = [None]  # the thread writing the resume checkpoint
    clock = Budget(minutes, t_start, backend, len(held_out), cfg.max_steps)

    def judged(held, sim_judge: float, validation=None, validation_beta=None, last: bool = False) -> None:
        """Curve row, checkpoints and progress for the pending fit (`last`: the run's last judgement). `validation`:
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
               "loss_max": learner.loss_max,  # the fit's largest minibatch loss: a spike shows here, not in `loss`
               "validation_success": None if validation is None else float(np.mean(validation["success"])),
               "validation_beta": validation_beta}
        curve.append(row)
        meta = _meta(cfg, i, env_steps, learner.norm)
        save(ckpt / f"policy_{i:03d}.msgpack", learner.params, meta)
        save(out / "policy.msgpack", learner.params, meta)
        # the first judgement's too: a run stopped in its first minute can be resumed, as its Ctrl-C line says
        if last or i == cfg.iterations - 1 or writer[0] is None or time.perf_counter() - saved > every:
            writer[0] = checkpoint(resume_path, cfg, learner, i, env_steps, curve, writer[0])
            saved = time.perf_counter()
        bar.set_postfix(success=f"{k / n:.1%}", loss=f"{loss:.4f}", steps=env_steps,
                        **({"pose_mm": f"{learner.pose_error_mm:.2f}"} if cfg.image else {}))
        bar.update(1)

    # On MJX every rollout has the held-out rows, so the scan compiles for one batch shape: the first
    # iteration's show the untrained student, unrecorded (a second shape cost ~8 s of a 5-minute budget,
    # notebook change 23); on cpu, nothing to compile, they are rolled only when there is a fit to judge.
    one_shape = backend != "cpu"
    for i in range(start, cfg.iterations):
        seeds, beta = cfg.train_seeds(i), np.full(cfg.envs, cfg.beta(i), np.float32)
        if pending is not None or one_shape:  # the last fit's judgement, in the same batch
            seeds, beta = np.concatenate([seeds, held_out]), np.concatenate([beta, np.zeros(len(held_out), np.float32)])
        if pending is not None and clock.spent(clock.rollout(len(seeds)) + clock.fit + clock.judge):
            break  # this iteration and the next fit's judgement would not fit: the pending fit is judged alone
        (x, y, n, outcome), sim = _timed(rollouts.padded, learner.params, learner.norm or _unit(cfg), seeds, beta, i,
                                         cfg.envs, clock.first_rollout(pending is None and not one_shape))
        clock.rolled(sim, len(seeds), rollouts.steps)
        if rollouts.cut:
            bar.write(f"iteration {i}'s rollout stopped at control step {rollouts.steps} of {cfg.max_steps} to keep "
                      f"the {minutes:g}-minute budget: its samples so far are learned from")
        _stop_if_non_finite(non_finite(outcome, seeds, x, y), f"iteration {i}'s rollout", curve, out)
        if pending is not None:
            held = {k: v[cfg.envs:] for k, v in outcome.items()}
            goal = until is not None and clock.agree(float(np.mean(held["success"])) >= until)
            stop = goal or clock.spent(clock.fit + clock.judge)  # a fit now would leave no time to judge it
            judged(held, 0.0, {k: v[:cfg.envs] for k, v in outcome.items()}, float(cfg.beta(i)), last=stop)
            pending = None
            if stop:
                curve[-1]["sim_seconds"] += sim  # spent, though the samples go unlearned: the judged policy is the run's
                break
        env_steps += n
        learner.add(x, y, keep=i == 0, n=n)
        learn = 0.0
        for part in range(cfg.fits(i)):
            if part and clock.spent(clock.fit + clock.judge):
                break  # a late fit more would leave no time to judge it
            if i == 0 and cfg.first_fits:  # from several initialisations, the lowest loss kept
                loss, seconds = _timed(_first_fit, learner, cfg.first_fits, out, bar,
                                       lambda took: not clock.spent(took + clock.judge))
            else:
                loss, seconds = _timed(learner.fit, i, part)
            learn += seconds
            clock.fit = seconds
            _stop_if_non_finite(None if np.isfinite(loss) else f"the loss is {loss}", f"iteration {i}'s fit", curve, out)
        pending = (i, loss, learn, sim)
    if pending is not None:
        seeds, n_train = held_out, 0
        if one_shape:  # the same shape again: training seeds ride along, their samples not learned
            seeds, n_train = np.concatenate([cfg.train_seeds(pending[0] + 1), held_out]), cfg.envs
        bar.write(f"judging iteration {pending[0]}'s policy on the {len(held_out)} held-out seeds: about "
                  f"{clock.judge:.0f} s")
        (_, _, _, held), sim_judge = _timed(rollouts.padded, learner.params, learner.norm, seeds, 0.0,
                                            cfg.iterations + pending[0], 0)
        _stop_if_non_finite(non_finite(held, seeds), f"iteration {pending[0]}'s judgement", curve, out)
        judged({k: v[n_train:] for k, v in held.items()}, sim_judge,
               {k: v[:n_train] for k, v in held.items()} if n_train else None, 0.0 if n_train else None, last=True)
    if writer[0] is not None:
        writer[0].join()
    if curve and curve[-1]["iteration"] < cfg.iterations - 1:
        why = reached(curve, until) or (f"another would pass the {minutes:g}-minute budget "
                                        f"({curve[-1]['wall_seconds']:.0f} s used)")
        bar.write(f"stopped after iteration {curve[-1]['iteration']}: {why}")
    bar.close()
    jax.block_until_ready(learner.params)
    kept = kept_fit(curve, keep)
    if kept is not None and kept["iteration"] != curve[-1]["iteration"]:
        shutil.copyfile(ckpt / f"policy_{kept['iteration']:03d}.msgpack", out / "policy.msgpack")
        bar.write(f"keeping iteration {kept['iteration']}'s policy: {kept['validation_success']:.1%} on its "
                  f"validation rollout (held-out {kept['success']:.1%})")
    summary = write_summary(cfg, backend, out, curve, rerun, kept=kept, keep=keep, devices=len(spread))
    # what the last held-out judgement took (or, judged in a rollout, would take alone): `mjx-pusht train` states it
    # as the time to expect of `evaluate` on the same seeds, before it starts
    return summary | {"judgement_seconds": round(sim_judge if pending is not None else clock.judge, 1)}


class Budget:
    """--minutes as a promise: an iteration's rollout, or a fit, starts only when it and the judgement of the fit it
    leaves fit in what is left, each predicted from the latest one measured (a run overshoots by the prediction's
    error, not by an iteration). With nothing measured yet (a run's first rollout and fit: it needs a policy), a
    MuJoCo C rollout that judges nothing stops stepping at a quarter of the time left, its samples kept: the
    rest is for the first fit and its judgement."""

    def __init__(self, minutes: float | None, t_start: float, backend: str, held_out: int, max_steps: int):
        self.deadline = None if minutes is None else t_start + 60 * minutes
        self.cpu, self.held_out, self.max_steps = backend == "cpu", held_out, max_steps
        self.last = self.step = self.fit = 0.0  # the latest rollout's seconds and seconds a control step; a fit's
        self.episodes = 1  # the latest rollout's

    def spent(self, seconds: float) -> bool:
        """Whether `seconds` more from now would pass the budget: by process 0's clock, where several processes train
        one run (each would otherwise stop at its own iteration, and the others wait for it)."""
        if self.deadline is None:
            return False
        return self.agree(time.perf_counter() + seconds > self.deadline)

    @staticmethod
    def agree(stop: bool) -> bool:
        """Process 0's `stop`, on every process of a run over several (each must end at the same iteration)."""
        import jax

        if jax.process_count() == 1:
            return stop
        from jax.experimental import multihost_utils

        return bool(multihost_utils.broadcast_one_to_all(np.bool_(stop)))

    def rolled(self, seconds: float, episodes: int, steps: int) -> None:
        self.last, self.step, self.episodes = seconds, seconds / max(steps, 1), episodes

    def rollout(self, episodes: int) -> float:
        """A rollout's predicted seconds: on MuJoCo C every control step as the latest's (a student's episodes may
        all run to the end), longer in proportion to more episodes, never shorter for fewer (a step's fixed costs:
        64 held-out episodes took 10 s where the 256 before them predicted 3); on MJX one batch shape, one scan of
        every step: the latest's."""
        return self.step * self.max_steps * max(1.0, episodes / self.episodes) if self.cpu else self.last

    @property
    def judge(self) -> float:
        """The last fit's judgement alone on the held-out seeds (on MJX, the same batch shape as a rollout)."""
        return self.rollout(self.held_out)

    def first_rollout(self, cuttable: bool) -> float | None:
        """The deadline of a rollout with nothing measured before it, if it may be cut (it judges nothing)."""
        if self.deadline is None or not cuttable:
            return None
        now = time.perf_counter()
        return now + max(self.deadline - now, 0.0) / 4


def dagger_env(cfg, backend: str):
    """The env DAgger's rollouts step: `cfg`'s starts, episode length, observations and drawn physics on `backend`
    (the held-out judgement rides in the same rollouts, so it is at the held-out seeds' own draws)."""
    from mjx_pusht.backends.base import has_gpu
    from mjx_pusht.backends.cpu import default_threads
    from mjx_pusht.envs.functional import PushTEnv

    # A rollout is one long jitted scan, where MJX's default CUDA-graph mode ("WARP": graphs keyed on buffer
    # addresses, which stay put inside the scan) replays its captures; the env's own default, staged, is for
    # stepping once a call. Measured on an H100: 491k against 287k control steps/s at 4,096 (notebook change 16).
    graph_mode = "WARP" if backend == "mjx-warp" and has_gpu() else None
    task = cfg.the_task
    # A pixel student's images on MJX are the raster renderer's, in its rollouts as in its fit (PushTEnv.images):
    # plain JAX ops, so every device of a data-parallel run draws its own worlds (MJX-Warp's ray tracer is an FFI
    # call with a render context of one device, which XLA cannot partition), and MJX-JAX trains from pixels too.
    return PushTEnv(backend=backend, reset_kind=cfg.reset, action_type=task.action_type, scene=task.scene(),
                    episode=cfg.episode(), threads=default_threads(), keep_states=False,
                    pixels=cfg.image, graph_mode=graph_mode, randomize=cfg.randomize, raster=backend != "cpu")


def non_finite(outcome: dict, seeds: np.ndarray, *arrays) -> str | None:
    """What went non-finite in a rollout (its episodes' states, by the env's own invariant, or its samples and
    labels), naming the first such seed; None when all is finite."""
    import jax.numpy as jnp

    bad = np.flatnonzero(~np.asarray(outcome["finite"], bool))
    if bad.size:
        return f"{bad.size} episodes' states went non-finite (first seed {int(seeds[bad[0]])})"
    if not all(bool(jnp.isfinite(a).all()) for a in arrays if a is not None and a.size):
        return "a sample or label went non-finite"
    return None


def _stop_if_non_finite(what: str | None, where: str, curve: list[dict], out: Path) -> None:
    """A non-finite rollout or fit ends the run in one line naming the iteration; the files of the last judged fit
    (policy.msgpack, its checkpoint, the resume file) were written before it and stay."""
    if what is not None:
        good = f"iteration {curve[-1]['iteration']}'s policy stays in {out / 'policy.msgpack'}" if curve else \
            "no policy was saved"
        raise TrainError(f"DAgger: in {where}, {what}; {good}")


def _unit(cfg):
    from mjx_pusht.train.policy import feature_size

    w = feature_size(cfg.obs_type, cfg.memory, cfg.goal_conditioned)
    return np.zeros(w, np.float32), np.ones(w, np.float32)


def _first_fit(learner, candidates: int, out: Path, bar, go_on) -> float:
    """Iteration 0's fit from `candidates` initialisations (DaggerConfig.first_fits), as many as the budget leaves
    time for (`go_on`): every candidate's loss goes to out/first_fits.json and the log, the kept one's is returned."""
    from mjx_pusht.io.outputs import atomic_write_json

    losses, kept = learner.fit_first(candidates, go_on)
    atomic_write_json(out / "first_fits.json", {"losses": losses, "kept": kept})
    short = f" (of {candidates}: the budget left time for no more)" if len(losses) < candidates else ""
    bar.write(f"first fit from {len(losses)} initialisations{short}, losses {', '.join(f'{v:.4f}' for v in losses)}: "
              f"kept {kept}")
    return losses[kept]


def _timed(fn, *args):
    import jax

    t0 = time.perf_counter()
    result = jax.block_until_ready(fn(*args))
    return result, time.perf_counter() - t0
