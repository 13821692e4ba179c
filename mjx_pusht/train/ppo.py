"""PPO from observations with Brax's own trainer (`brax.training.agents.ppo.train`), unchanged.

The environment is the Brax adapter (`envs/brax.py`): the env's own control step, fresh task
starts on every reset (`wrap_for_training`). Brax trains on a reward designed for learning;
success is never judged by it, only by the task's rule (coverage >= 0.95, or --success-threshold, within the episode's
control steps) on held-out seeds, by the same code the `policy:PATH` controller runs.

The training reward, per control step (`training_reward`):

    r = (coverage(s') - 1) + SUCCESS_BONUS * success(s') + SHAPING * (phi(s') - phi(s))
    phi(s) = -(|tee position error| / L + |tee yaw error| / 1 rad + |pusher to the T| / L) / 3

L is 0.1 m on the chapter's scene (`shaping_length`: its arena's width over 7.8) and the same fraction of
gym-pusht's (0.064 m), so the shaping weighs a start's distance from the goal alike on either task (--task).

The first term is the env's own reward (the coverage, what gym-pusht pays) less 1: a cost for every
step not yet covered. Success ends the episode, so a reward of plain coverage made *not* succeeding
the better policy: staying at 0.8 coverage is worth 0.8 / (1 - 0.97) ~ 27 discounted, more than the
bonus and the end (measured on the H100, notebook change 17: PPO's held-out coverage rose to 0.79 in two
minutes and stayed there, success under 1.5%). With the cost, every step short of success loses and
ending it is the best outcome (a test checks this). The bonus marks the end the task asks for; the
shaping term is potential-based (Ng et al., 1999), so it changes how fast PPO finds the task, not
which policy is best: it pays for moving the T toward its target pose and the pusher toward the T,
the two things a random policy almost never does on its own.

The policy Brax learns (an MLP on Brax's running observation normalisation, tanh-squashed
Gaussian) is saved as a `policy:PATH` checkpoint (policy.py): the normaliser's mean and std, the
layers, and which action it acts with (ppo_policy.py): by default a draw from the Gaussian keyed
by seed and step, the policy PPO trains; or its mean, tanh(loc), Brax's own `make_policy(...,
deterministic=True)` (tests check both against Brax). The mean action is not what PPO optimises:
it stalls where the trained policy's noise carries it on, and its held-out rate swung 5-93%
between judgements while PPO learned (docs/notebook/training.md), so every judgement measures
both, and `--keep best` chooses by validation seeds, never the held-out ones.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from mjx_pusht.errors import ConfigError, needs
from mjx_pusht.io.outputs import atomic_write_bytes
from mjx_pusht.train.dagger import held_out_seeds
from mjx_pusht.train.policy import OBS_SIZE, PPO_ACTS
from mjx_pusht.train.resume import TrainError, config_dict, resume_tree

SUCCESS_BONUS = 10.0
SHAPING = 10.0
TABLE = 65536  # the training starts: task seeds 0 .. TABLE - 1 (BraxPushT's table)
RESUME = "resume.msgpack"  # in checkpoints/: Brax's params and the curve after the last judgement
# the flags `train --algo ppo` sets these fields from: an error names the field (a Python caller's word) and the
# flag (the CLI user's); unroll_length and validation_envs have none
_FLAGS = {"envs": "--envs", "timesteps": "--timesteps", "evals": "--iterations", "eval_envs": "--eval-envs",
          "max_steps": "--max-steps", "batch_size": "--batch", "num_minibatches": "--minibatches"}


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    obs_type: str = "state"
    envs: int = 4096  # parallel training envs
    timesteps: int = 50_000_000  # env control steps in all
    evals: int = 20  # held-out judgements (and checkpoints) over the run
    hidden: tuple[int, ...] = (256, 256, 256)  # the policy's hidden widths (the value net: Brax's default)
    learning_rate: float = 3e-4
    entropy_cost: float = 1e-2
    discounting: float = 0.97
    unroll_length: int = 20
    batch_size: int = 256  # Brax's: unrolls per minibatch
    num_minibatches: int = 32
    updates_per_batch: int = 4
    reward_scaling: float = 0.1
    reset: str = "task"
    eval_envs: int = 4096
    max_steps: int = 300
    seed: int = 0
    act: str = "sample"  # the saved policy's action (ppo_policy.py): "sample", what PPO trains, or "mean"
    validation_envs: int = 0  # --keep best judges on this many seeds, neither trained on nor held out (0: eval_envs / 4)
    # Brax's limits on an update. max_grad_norm: the gradient's global norm clipped to this before Adam (None:
    # unclipped). Measured on one H100 (docs/notebook/lead3.md): unclipped, two 10-minute runs fell from 99-100% to
    # 0-6% eight times in 57 judgements, each after an epoch whose KL was 1.1-51 (0.02-0.07 otherwise): a sharp
    # policy (sigma ~0.005) gives one minibatch a gradient far above those Adam has seen. Clipped at 1.0, three runs
    # held 99.3-100% from their third judgement on, epoch KL <= 0.14.
    max_grad_norm: float | None = 1.0
    lr_schedule: str | None = None  # "adaptive-kl": Brax's ADAPTIVE_KL, the rate /1.5 or x1.5 toward desired_kl 0.01
    success_threshold: float | None = None  # the coverage an episode succeeds at; None: the task's (0.95)
    # Physics drawn per episode from its seed in training (the Brax adapter's table) and every judgement, as DAgger's
    # (DaggerConfig.randomize); None: the scene's own (a resume file from before this setting existed still matches)
    randomize: tuple | None = None
    # The task trained and judged on (task/tasks.TASKS), as DaggerConfig.task; None: the chapter's (a resume file
    # from before this setting existed still matches). The policy acts in velocities on either task (envs/brax.py).
    task: str | None = None

    def __post_init__(self) -> None:
        if self.randomize is not None:
            from mjx_pusht.model.randomize import check

            object.__setattr__(self, "randomize", check(self.randomize, self.the_task.scene(), "--randomize") or None)
        self.the_task.check_reset(self.reset)
        if self.act not in PPO_ACTS:
            raise ConfigError(f"PPO acts with its Gaussian's {' or '.join(PPO_ACTS)}, not {self.act!r}")
        if self.obs_type not in ("state", "keypoints"):
            raise ConfigError(f"PPO trains from state or keypoints observations, not {self.obs_type!r}")
        if self.lr_schedule not in (None, "adaptive-kl"):
            raise ConfigError(f"PPO: --lr-schedule is adaptive-kl (or not given: constant), not {self.lr_schedule!r}")
        if self.max_grad_norm is not None and not self.max_grad_norm > 0:
            raise ConfigError(f"PPO: --max-grad-norm must be above 0, got {self.max_grad_norm}")
        self.episode()  # a success threshold outside (0, 1] is a one-line error now
        if self.validation_envs < 0:
            raise ConfigError(f"PPO: validation_envs must be at least 0, got {self.validation_envs}")
        for name in ("envs", "timesteps", "evals", "eval_envs", "max_steps", "unroll_length", "batch_size",
                     "num_minibatches"):
            if int(getattr(self, name)) < 1:
                flag = f" ({_FLAGS[name]})" if name in _FLAGS else ""
                raise ConfigError(f"PPO: {name}{flag} must be at least 1, got {getattr(self, name)}")
        per_epoch = self.batch_size * self.num_minibatches * self.unroll_length  # Brax's env steps per update round
        if (self.batch_size * self.num_minibatches) % self.envs:
            raise ConfigError(f"PPO: --batch x minibatches ({self.batch_size} x {self.num_minibatches}) must be a "
                              f"multiple of --envs ({self.envs}), as Brax requires")
        if self.timesteps < per_epoch * self.evals:
            raise ConfigError(f"PPO: --timesteps {self.timesteps} is fewer than one round of {per_epoch} env steps "
                              f"(--batch x {self.num_minibatches} minibatches x unroll {self.unroll_length}) per "
                              f"judgement ({self.evals})")

    @property
    def the_task(self):
        from mjx_pusht.task.tasks import get

        return get(self.task or "chapter")

    def episode(self):
        """The episodes trained and judged on: the task's, at `max_steps` and `success_threshold`."""
        return self.the_task.episode(max_steps=self.max_steps, success_threshold=self.success_threshold)

    def reward(self):  # `training_reward` at this task's scene's shaping length
        return lambda prev, s: training_reward(prev, s, shaping_length(self.the_task.variant))

    def held_out_seeds(self) -> np.ndarray:
        return held_out_seeds(self.eval_envs)  # the same held-out task seeds as DAgger's

    def validation_seeds(self) -> np.ndarray:
        """Task seeds past the training table (BraxPushT draws its starts from seeds 0 .. TABLE - 1)."""
        return TABLE + np.arange(self.validation_envs or max(8, self.eval_envs // 4), dtype=np.int64)


def shaping_length(variant: str) -> float:
    """The shaping's length scale on a scene variant, m: 0.1 between the chapter's walls, 0.78 m apart; the same
    fraction of gym-pusht's, 497 px (mm) apart, 0.064 (its T and pusher are the chapter's: its arena is smaller)."""
    from mjx_pusht.model import gym_pusht as frame
    from mjx_pusht.task.rules import WORKSPACE_HALF

    lo, hi = frame.WALL_INNER_PX
    return 0.1 if variant == "chapter" else 0.1 * (hi - lo) * frame.PX / (2 * WORKSPACE_HALF)


def training_reward(prev, s, length: float = 0.1):
    """The reward PPO is trained on (module docstring), from one world's env states before and after a step;
    `length`: the shaping's length scale (`shaping_length`), the chapter's by default."""
    import jax.numpy as jnp

    from mjx_pusht.task.rules import distance_to_tee, wrap_angle

    def phi(state):
        x = state.obs["state"]
        pose = x[2:5]
        far = jnp.linalg.norm(pose[:2]) / length + jnp.abs(wrap_angle(pose[2])) / 1.0
        reach = distance_to_tee(x[0:2], pose) / length
        return -(far + reach) / 3.0

    m = s.metrics
    return (m["coverage"] - 1.0) + SUCCESS_BONUS * m["success"].astype(m["coverage"].dtype) + SHAPING * (phi(s) - phi(prev))


def to_checkpoint(params, obs_type: str, act: str = "mean") -> tuple[dict, dict]:
    """Brax's (normaliser, policy, value) params -> (layers, meta) of a policy.py checkpoint."""
    normalizer, policy = params[0], params[1]
    layers = policy["params"]
    names = sorted((k for k in layers if k.startswith("hidden_")), key=lambda k: int(k.split("_")[1]))
    dense = {f"Dense_{i}": {"kernel": np.asarray(layers[k]["kernel"]), "bias": np.asarray(layers[k]["bias"])}
             for i, k in enumerate(names)}
    meta = {"method": "ppo", "obs_type": obs_type, "activation": "silu", "act": act,
            "in_mean": [float(v) for v in np.asarray(normalizer.mean)],
            "in_std": [float(v) for v in np.asarray(normalizer.std)]}
    return dense, meta


def _judge(env, cfg: PPOConfig):
    """A jitted judge: checkpoint layers and meta -> {"mean", "sample"} x {"held_out", "validation"} per-episode
    success and final coverage, and the count of episodes whose observation went non-finite. Both actions run in one
    batch (held-out and validation seeds, each twice), so judging the action not saved costs little on a GPU."""
    import jax
    import jax.numpy as jnp

    from mjx_pusht.train.ppo_policy import ppo_action

    held, val = cfg.held_out_seeds(), cfg.validation_seeds()
    seeds = np.concatenate([held, val, held, val])
    sample = jnp.asarray(np.repeat([0.0, 1.0], len(held) + len(val)), jnp.float32)
    s0 = env.reset(seeds)

    def episode(dense, mean, std, s, noise):
        meta = {"in_mean": mean, "in_std": std, "activation": "silu"}

        def body(s, _):
            obs = s.obs[cfg.obs_type]
            action = cfg.the_task.from_velocity(ppo_action(dense, meta, obs, s.key, s.step, noise), s.obs)
            return env.advance_one(s, action), None

        s, _ = jax.lax.scan(body, s, None, cfg.max_steps)
        return s.metrics["success"], s.metrics["coverage"], jnp.isfinite(s.obs[cfg.obs_type]).all()

    run = jax.jit(jax.vmap(episode, in_axes=(None, None, None, 0, 0)))

    def judge(dense, meta):
        success, cov, finite = (np.asarray(v) for v in run(dense, jnp.asarray(meta["in_mean"], jnp.float32),
                                                             jnp.asarray(meta["in_std"], jnp.float32), s0, sample))
        n, out = len(held) + len(val), {"non_finite": int((~finite).sum())}
        for i, act in enumerate(PPO_ACTS):
            parts = {"held_out": slice(i * n, i * n + len(held)), "validation": slice(i * n + len(held), (i + 1) * n)}
            for name, part in parts.items():
                out[act, name] = (success[part].astype(bool), cov[part].astype(float))
        return out

    return judge


def _std_change(before, after) -> float | None:
    """The largest relative change of the observation normaliser's std over the inputs since the last judgement:
    one far-out training observation moves it at once (Brax's running statistics), and every input the policy
    sees with it (a suspect for a collapse, recorded per judgement as `norm_std_change`)."""
    if before is None:
        return None
    return float(np.max(np.abs(np.asarray(after) / np.asarray(before) - 1.0)))


def _finite(tree) -> bool:
    import jax

    return all(bool(np.isfinite(np.asarray(x)).all()) for x in jax.tree.leaves(tree))


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
    sigma, its largest and least pre-tanh mean), and norm_std_change (`_std_change`).
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
    judge = _judge(PushTEnv(backend=backend, reset_kind=cfg.reset, action_type=task.action_type, episode=episode,
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
        if not _finite(params):  # the normaliser's running mean holds every training observation: one NaN reaches it
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
                     | {"norm_std_change": _std_change(last["in_std"], meta["in_std"])})
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


def weights_digest(params, obs_type: str) -> str:
    """16 hex digits of SHA-256 over the policy's layers as float32 (the checkpoint's `Dense_i` kernels and biases,
    in the order jax.tree.leaves gives a loaded checkpoint's): equal digests, equal weights."""
    import hashlib

    import jax

    dense, _ = to_checkpoint(params, obs_type)
    return hashlib.sha256(b"".join(np.asarray(a, np.float32).tobytes() for a in jax.tree.leaves(dense))).hexdigest()[:16]


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
