"""PPO from observations with Brax's own trainer (`brax.training.agents.ppo.train`), unchanged.

The environment is the Brax adapter (`envs/brax.py`): the env's own control step, fresh task
starts on every reset (`wrap_for_training`). Brax trains on a reward designed for learning;
success is never judged by it, only by the task's rule (coverage >= 0.95, or --success-threshold, within the episode's
control steps) on held-out seeds, by the same code the `policy:PATH` controller runs.

How it is configured and what it is rewarded for: ppo_config.py; how each judgement judges: ppo_judge.py.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from mjx_pusht.errors import needs
from mjx_pusht.io.outputs import atomic_write_bytes
from mjx_pusht.train.policy import OBS_SIZE, PPO_ACTS
from mjx_pusht.train.ppo_config import SHAPING, SUCCESS_BONUS, TABLE, PPOConfig, shaping_length, training_reward
from mjx_pusht.train.ppo_judge import finite, make_judge, std_change, to_checkpoint, weights_digest
from mjx_pusht.train.resume import TrainError, config_dict, resume_tree

# PPO's names as they were before its config and judging had modules of their own
__all__ = ["PPOConfig", "SHAPING", "SUCCESS_BONUS", "TABLE", "graph_mode", "shaping_length", "to_checkpoint", "train_ppo",
           "training_reward", "weights_digest"]

RESUME = "resume.msgpack"  # in checkpoints/: Brax's params and the curve after the last judgement


class _Stop(Exception):
    """Raised from Brax's `progress_fn` once --minutes is spent or --until reached (or from `policy_params_fn`, when
    the untrained policy's judgement reaches --until): Brax's trainer has no stop of its own, and those callbacks run
    on the host between training epochs, the policy judged and saved. Its message is the line the run ends with."""


def graph_mode(backend: str, devices: int | None) -> str | None:
    """MJX-Warp's CUDA-graph mode for Brax's training env: on several GPUs "WARP", a graph per device (the env's
    staged default keeps one graph per call site, which Brax's pmap replays on every GPU and fails: lead13, lead15;
    WARP trained PPO on 2 and 4 H200s to 96-100%: lead19); else the env's default (None). An
    MJX_PUSHT_ENV_GRAPH_MODE the env reads itself is the user's, unless it names a mode that failed on several GPUs:
    a one-line TrainError (`train` asks before it writes anything)."""
    import jax

    from mjx_pusht.backends.base import has_gpu

    several = backend == "mjx-warp" and (len(jax.local_devices()) if devices is None else devices) > 1
    asked = os.environ.get("MJX_PUSHT_ENV_GRAPH_MODE")
    if several and asked not in (None, "WARP", "NONE"):
        raise TrainError(f"--algo ppo on mjx-warp over {devices or len(jax.local_devices())} devices: "
                         f"MJX_PUSHT_ENV_GRAPH_MODE={asked} fails under Brax's pmap on several GPUs "
                         "(docs/training.md); unset it (a graph per device, WARP, is the default there), or "
                         "--devices 1, or --backend mjx-jax")
    return "WARP" if several and asked is None and has_gpu() else None


def train_ppo(cfg: PPOConfig, backend: str, out: Path, *, resume: bool = False, progress: bool = True,
              minutes: float | None = None, keep: str = "last", devices: int | None = None,
              until: float | None = None) -> tuple[list[dict], str | None]:
    """Brax PPO on the adapter, judged on the held-out seeds at every evaluation; returns the curve and a digest of
    the weights Brax ended with (`weights_digest`; on several processes, checked the same on every one).

    Each curve row has the held-out success of the action the policy is saved with (`cfg.act`) and of both
    actions (success_mean, success_sample), the saved action's success on the validation seeds, and Brax's own
    loss metrics of the epoch before it (brax_*: policy, value and entropy losses, KL, the Gaussian's mean and least
    sigma, its largest and least pre-tanh mean), and norm_std_change (`ppo_judge.std_change`).
    `resume`: go on from the last judged policy in `out` (Brax's `restore_params`: the normaliser, policy and
    value networks; Brax restores no optimiser state, so Adam starts afresh) up to `cfg.timesteps`.
    `minutes`: stop at the first judgement past this much training wall-clock (resumable from there). `until`: stop at
    the first judgement whose held-out success is at least this.
    `keep`: "best": policy.msgpack is the judged policy with the highest validation success (never chosen by
    the held-out seeds); "last": the last judged. `devices`: this host's devices Brax maps its training over
    (its max_devices_per_host; None: every one), each its share of the envs and of every minibatch. A non-finite network, observation statistic or judged episode
    stops the run with a TrainError naming the judgement; the files of the last good one stay.
    Over several processes (jax.distributed; Brax maps its epochs over every process's devices) process 0 alone
    judges and writes: Brax calls back there alone, past its first call (the untrained policy), which the others skip."""
    import functools

    import jax

    needs("train_ppo", "train")  # one line naming the extra, before any work
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as brax_ppo
    from tqdm import tqdm

    from mjx_pusht.envs.brax import BraxPushT, wrap_for_training
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.study.distributed import every_process
    from mjx_pusht.study.stats import wilson
    from mjx_pusht.train.policy import save
    from mjx_pusht.train.curve import kept as kept_row
    from mjx_pusht.train.curve import reached, write_curve

    ckpt = out / "checkpoints"
    restored, curve = _load_resume(ckpt / RESUME, cfg) if resume else (None, [])
    done = curve[-1]["env_steps"] if curve else 0
    evals_left = cfg.evals - (len(curve) - 1) if curve else cfg.evals
    if resume and (cfg.timesteps <= done or evals_left < 1):
        raise TrainError(f"--resume: the run in {out} already reached {done:,} env steps and {len(curve) - 1} "
                         "judgements; raise --timesteps and --iterations to go on")
    episode = cfg.episode()
    task = cfg.the_task
    env = BraxPushT(backend=backend, obs_type=cfg.obs_type, reset_kind=cfg.reset, episode=episode,
                    max_worlds=max(cfg.envs, 128), table=TABLE, reward_fn=cfg.reward(), randomize=cfg.randomize,
                    task=task.name, graph_mode=graph_mode(backend, devices))
    lead, many = jax.process_index() == 0, jax.process_count() > 1
    # Every process builds the judge and runs the first judgement, though Brax calls back on process 0 alone after
    # its first call: MJX-Warp names each FFI call a process registers by a counter of its own, so a process that
    # compiled the judge before Brax's epoch lowered that epoch to another HLO text than one that did not
    # (`..._func_wrapper_3` against `_1`), and the processes hung in its compile (study/distributed.py's
    # same_program_text has why, notebook lead23). The others' judgement is thrown away.
    judge = make_judge(PushTEnv(backend=backend, reset_kind=cfg.reset, action_type=task.action_type, episode=episode,
                            scene=task.scene(), keep_states=False, randomize=cfg.randomize), cfg)
    ckpt.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter() - (curve[-1]["wall_seconds"] if curve else 0.0)
    last = {"t": time.perf_counter(), "skip": resume, "params": None, "first": True,
            "in_std": None if restored is None else np.asarray(restored[0].std)}  # a resumed run's normaliser
    bar = tqdm(total=cfg.evals + 1, initial=len(curve), desc="ppo", unit="eval", disable=not progress)

    def bad(step: int, what: str) -> TrainError:
        good = f"judgement {len(curve) - 1}'s policy stays in {out / 'policy.msgpack'}" if curve else "nothing was saved"
        return TrainError(f"PPO: {what} at judgement {len(curve)} ({step:,} env steps); {good}")

    def on_params(step, make_policy, params):
        if lead:
            judged(step, params)
        elif last["first"]:  # the same programs compiled in the same order as process 0's (above); a resumed
            # run's process 0 skips this judgement, so --resume over processes (refused today) would have to skip it too
            judge(*to_checkpoint(params, cfg.obs_type, cfg.act))
        if many and last["first"]:
            # Brax's first call is on every process, the others on process 0 alone. Every process leaves the first
            # together: the others would otherwise wait in the first epoch's all-reduce while process 0 compiles and
            # runs its judgement, and on CPU devices gloo gives up connecting after a fixed time (a two-process test
            # failed so under a loaded CI machine: "Gloo context initialization failed ... Connect timeout")
            every_process("ppo-first-judgement", "")
        last["first"] = False

    def judged(step, params):
        if last["skip"]:  # a resumed run's first call: the restored policy, judged already
            last["skip"] = False
            return
        step = int(step) + done
        if not finite(params):  # the normaliser's running mean holds every training observation: one NaN reaches it
            raise bad(step, "a training observation, the normaliser or the networks went non-finite")
        t_judge = time.perf_counter()
        dense, meta = to_checkpoint(params, cfg.obs_type, cfg.act)
        meta |= {"iteration": len(curve), "env_steps": int(step), "config": config_dict(cfg)}
        judged = judge(dense, meta)
        if judged["non_finite"]:
            raise bad(step, f"{judged['non_finite']} judged episodes' observations went non-finite")
        success, cov = judged[cfg.act, "held_out"]
        k, n = int(success.sum()), len(success)
        lo, hi = wilson(k, n)
        now = time.perf_counter()
        t_judge = now - t_judge
        curve.append({"iteration": len(curve), "beta": 0.0, "env_steps": int(step), "samples": int(step),
                      "loss": None, "success": k / n, "success_lo": lo, "success_hi": hi,
                      "coverage": float(cov.mean()), "sim_seconds": t_judge,
                      "learn_seconds": now - last["t"] - t_judge if curve else 0.0, "wall_seconds": now - t0,
                      "validation_success": float(judged[cfg.act, "validation"][0].mean()), "validation_beta": 0.0}
                     | {f"success_{a}": float(judged[a, "held_out"][0].mean()) for a in PPO_ACTS}
                     | {"norm_std_change": std_change(last["in_std"], meta["in_std"])})
        last["t"], last["params"], last["in_std"] = now, params, meta["in_std"]
        save(ckpt / f"policy_{len(curve) - 1:03d}.msgpack", dense, meta)
        save(out / "policy.msgpack", dense, meta)
        write_curve(out, curve, f"Brax PPO from {cfg.obs_type} (running)", rerun=False)  # a killed run keeps its curve
        _save_resume(ckpt / RESUME, cfg, params, curve)
        bar.update(1)
        bar.set_postfix(success=f"{k / n:.1%}", steps=int(step))
        why = reached(curve, until) if len(curve) == 1 else None  # the untrained policy: no epoch's metrics to wait for
        if why:
            raise _Stop(why)

    def on_metrics(step, metrics):
        """Brax's loss metrics of the epoch that made the last judged policy (called after on_params)."""
        names = {"policy_loss": "policy_loss", "v_loss": "v_loss", "entropy_loss": "entropy_loss", "kl_mean": "kl",
                 "policy_dist_mean_std": "sigma", "policy_dist_min_std": "sigma_min", "policy_dist_max_loc": "loc_max",
                 "policy_dist_min_loc": "loc_min", "total_loss": "total_loss"}
        if curve and last["params"] is not None:
            curve[-1].update({f"brax_{v}": float(metrics[f"training/{k}"]) for k, v in names.items()
                              if f"training/{k}" in metrics})
            write_curve(out, curve, f"Brax PPO from {cfg.obs_type} (running)", rerun=False)
            _save_resume(ckpt / RESUME, cfg, last["params"], curve)
        why = reached(curve, until)
        if why:
            raise _Stop(why)
        if minutes is not None and curve and curve[-1]["wall_seconds"] > 60 * minutes:
            raise _Stop(f"the {minutes:g}-minute budget is spent")

    final = None
    try:
        _, final, _ = brax_ppo.train(
            environment=env, num_timesteps=cfg.timesteps - done, num_envs=cfg.envs, episode_length=cfg.max_steps,
            wrap_env_fn=wrap_for_training, learning_rate=cfg.learning_rate, entropy_cost=cfg.entropy_cost,
            discounting=cfg.discounting, unroll_length=cfg.unroll_length, batch_size=cfg.batch_size,
            num_minibatches=cfg.num_minibatches, num_updates_per_batch=cfg.updates_per_batch,
            reward_scaling=cfg.reward_scaling, normalize_observations=True, seed=cfg.seed + len(curve),
            num_evals=evals_left + 1, run_evals=False, policy_params_fn=on_params, progress_fn=on_metrics,
            restore_params=restored, max_grad_norm=cfg.max_grad_norm, max_devices_per_host=devices,
            **({"learning_rate_schedule": "ADAPTIVE_KL"} if cfg.lr_schedule == "adaptive-kl" else {}),
            network_factory=functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=cfg.hidden))
    except _Stop as why:
        bar.write(f"stopping after judgement {len(curve) - 1}: {why}")
        final = last["params"]
    bar.close()
    digest = weights_digest(final, cfg.obs_type) if final is not None else None
    if many:  # one run: the all-reduced gradients left every process the same weights
        digests = every_process("ppo-final-weights", digest)
        if len(set(digests)) > 1:
            raise RuntimeError(f"PPO over {len(digests)} processes ended with different weights (digests "
                               f"{', '.join(digests)}): their gradients were not averaged across processes")
    kept = kept_row(curve, keep)
    if kept is not None and kept["iteration"] != curve[-1]["iteration"]:
        shutil.copyfile(ckpt / f"policy_{kept['iteration']:03d}.msgpack", out / "policy.msgpack")
        print(f"keeping judgement {kept['iteration']}'s policy: {kept['validation_success']:.1%} on the "
              f"{len(cfg.validation_seeds())} validation seeds (held-out {kept['success']:.1%})")
    return curve, digest


def _save_resume(path: Path, cfg: PPOConfig, params, curve: list[dict]) -> None:
    """Brax's (normaliser, policy, value) params and the curve, written whole: what --resume starts from."""
    import jax
    from flax import serialization

    tree = {"config": json.dumps(config_dict(cfg), sort_keys=True), "curve": json.dumps(curve),
            "normalizer": serialization.to_state_dict(jax.tree.map(np.asarray, params[0])),
            "policy": jax.tree.map(np.asarray, params[1]), "value": jax.tree.map(np.asarray, params[2])}
    atomic_write_bytes(path, serialization.msgpack_serialize(tree))


def _load_resume(path: Path, cfg: PPOConfig):
    import jax
    import jax.numpy as jnp
    from brax.training.acme import running_statistics, specs
    from flax import serialization

    tree = resume_tree(path, cfg, ("timesteps", "evals"))
    try:
        curve = json.loads(tree["curve"])
        template = running_statistics.init_state(specs.Array((OBS_SIZE[cfg.obs_type],), jnp.float32))
        normalizer = serialization.from_state_dict(template, jax.tree.map(jnp.asarray, tree["normalizer"]))
        params = (normalizer, jax.tree.map(jnp.asarray, tree["policy"]), jax.tree.map(jnp.asarray, tree["value"]))
    except Exception as e:  # noqa: BLE001 - any decoding failure means the same thing to the user
        raise TrainError(f"--resume: {path} is unreadable ({type(e).__name__}); start again without --resume") from None
    return params, curve
