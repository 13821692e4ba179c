"""A policy trained on gym-pusht's task as gym-pusht's own controller: its observation in, its action out.

    import gymnasium as gym
    import gym_pusht  # noqa: F401  (registers gym_pusht/PushT-v0)
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    policy = GymPushtPolicy("outputs/train/policy.msgpack")      # from `mjx-pusht train --task gym-pusht`
    env = gym.make("gym_pusht/PushT-v0", obs_type=policy.obs_type)  # "state", or "pixels_agent_pos" from pixels
    obs, info = env.reset(seed=0)
    policy.reset()                                                   # at every episode's start: its memory
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            break

No part of this project's physics runs: gym-pusht's observation (pixels, y down) is mapped to the world frame the
policy was trained in (model/gym_pusht.py's exact maps), the policy acts as `--controller policy:PATH` does, and
its velocity becomes the pixel target gym-pusht's PD law settles to moving at it (task/tasks.py). A state or
keypoints policy reads gym-pusht's `state` observation (agent x, y, block x, y, angle); a pixel policy reads
`pixels_agent_pos` (the 96 x 96 image and the agent's position), as LeRobot's gym-pusht policies do.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.controllers import ControllerError, seed_key
from mjx_pusht.task.rules import observe
from mjx_pusht.task.tasks import TASKS, as_targets


class GymPushtPolicy:
    """A checkpoint of `mjx-pusht train --task gym-pusht` as a function of gym-pusht's observation."""

    def __init__(self, path, seed: int = 0):
        from mjx_pusht.train.policy import load_policy

        self.controller = load_policy(f"policy:{path}")
        meta = self.controller.meta
        task = (meta.get("config") or {}).get("task") or "chapter"
        if task not in TASKS or TASKS[task].variant != "gym-pusht":  # gym-pusht's task, or its easy variant
            raise ControllerError(f"policy {path} was trained on the {task} task, not gym-pusht's (train --task gym-pusht)")
        if self.controller.reads_goal:
            raise ControllerError(f"policy {path} reads a goal per episode (train --goal random); gym-pusht's is fixed")
        self.obs_type = "pixels_agent_pos" if self.controller.pixels else "state"
        self._targets = as_targets(self.controller)
        self._key = seed_key([seed])  # a sampling policy's draws are keyed by seed and step
        self.reset()

    def reset(self) -> None:
        """Forget the last episode: the policy's memory, and the step count."""
        self._carry, self._t = self._targets.init(self._key), 0

    def __call__(self, obs) -> np.ndarray:
        """gym-pusht's action (2,) float32: the agent's target in its pixels, for `obs` of `self.obs_type`."""
        if self.obs_type == "state":
            s = np.asarray(obs, np.float64).reshape(5)
            agent, tee = s[None, 0:2], frame.pose_to_world(s[None, 2:4], s[None, 4])
        else:
            agent, tee = np.asarray(obs["agent_pos"], np.float64).reshape(1, 2), np.zeros((1, 3))
        world = observe(frame.to_world(agent), tee)
        if self.obs_type != "state":  # a pixel policy reads the T from the image alone (its state is not given)
            world["pixels"] = np.asarray(obs["pixels"], np.uint8)[None]
        target, self._carry = self._targets.act(self._carry, world, self._t, self._key)
        self._t += 1
        return np.clip(frame.to_px(np.asarray(target, np.float64))[0], 0.0, 512.0).astype(np.float32)
