"""PPO's configuration (`PPOConfig`, every setting checked when made) and the reward Brax trains on.

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
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.train.dagger_config import held_out_seeds
from mjx_pusht.train.policy import PPO_ACTS

SUCCESS_BONUS = 10.0
SHAPING = 10.0
TABLE = 65536  # the training starts: task seeds 0 .. TABLE - 1 (BraxPushT's table)
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
