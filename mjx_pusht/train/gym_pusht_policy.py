"""A policy trained on gym-pusht's task as gym-pusht's own controller: its observation in, its action out.

    import gymnasium as gym
    import gym_pusht  # noqa: F401  (registers gym_pusht/PushT-v0)
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    policy = GymPushtPolicy("outputs/train/policy.msgpack")      # from `mjx-pusht train --task gym-pusht`
    env = gym.make("gym_pusht/PushT-v0", obs_type=policy.obs_type)  # "state", or "pixels_agent_pos" from pixels
    obs, info = env.reset(seed=0)
    policy.reset(seed=0)                                             # at every episode's start: its memory
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        if terminated or truncated:
            break

No part of this project's physics runs: gym-pusht's observation (pixels, y down, the angle in [0, 2 pi)) is mapped
to the world frame the policy was trained in by task/gym_pusht_obs.py, the one door `eval --backend gym-pusht` goes
through too (so an eval there is this loop, episode for episode; `reset(seed=...)` keys a sampling policy's draws as
eval does), the policy acts as `--controller policy:PATH` does, and its velocity becomes the pixel target gym-pusht's PD law settles to moving at it (task/tasks.py). A state or
keypoints policy reads gym-pusht's `state` observation (agent x, y, block x, y, angle); a pixel policy reads
`pixels_agent_pos` (the 96 x 96 image and the agent's position), as LeRobot's gym-pusht policies do.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht import validate
from mjx_pusht.api import keywords
from mjx_pusht.boundary import check_gym_pusht_obs
from mjx_pusht.task.controllers import ControllerError, seed_key
from mjx_pusht.task.gym_pusht_obs import controller_obs, gym_pusht_action
from mjx_pusht.task.tasks import TASKS, as_targets


class GymPushtPolicy:
    """A checkpoint of `mjx-pusht train --task gym-pusht` as a function of gym-pusht's observation."""

    @keywords  # an unknown keyword: one line naming the known ones
    def __init__(self, path, seed: int = 0):
        import os

        from mjx_pusht.train.policy import load_policy

        seed = validate.seed(seed)
        if seed is None:  # reset(seed=None) keeps the key; the policy's own seed is one (was numpy's TypeError)
            raise ControllerError("seed must be an integer from 0 to 2**63-1, got None (reset(seed=None) keeps it)")
        if not isinstance(path, (str, os.PathLike)):
            raise ControllerError(f"path must be a policy file's path (a str or a Path), got {type(path).__name__}")
        self.controller = load_policy(f"policy:{path}")
        meta = self.controller.meta
        TASKS["gym-pusht"].check_policy(self.controller, f"policy {path}")  # as eval and demos check it
        task = (meta.get("config") or {}).get("task")
        if self.controller.reads_goal:
            raise ControllerError(f"policy {path} reads a goal per episode (train --goal random); gym-pusht's is fixed")
        self.obs_type = "pixels_agent_pos" if self.controller.pixels else "state"
        self.task = task
        self._targets = as_targets(self.controller)
        self._key = seed_key([seed])  # a sampling policy's draws are keyed by seed and step
        self.reset()

    @keywords  # as __init__: a keyword it does not take, one line
    def reset(self, seed: int | None = None) -> None:
        """Forget the last episode: the policy's memory, and the step count. `seed`: the episode's (the one given to
        `env.reset`), which keys a sampling policy's draws as `eval` keys them, so the episode is eval's to the bit."""
        if seed is not None:
            self._key = seed_key([validate.seed(seed)])
        self._carry, self._t = self._targets.init(self._key), 0

    @keywords  # an action per observation: a second argument is one line, not a TypeError
    def __call__(self, obs) -> np.ndarray:
        """gym-pusht's action (2,) float32: the agent's target in its pixels, for `obs` of `self.obs_type`."""
        check_gym_pusht_obs(obs, self.obs_type)  # a wrong, non-finite or foreign observation: one line, no NaN out
        if self.obs_type == "state":
            one = np.asarray(obs)[None]
        else:
            one = {k: np.asarray(obs[k])[None] for k in ("pixels", "agent_pos")}
            if one["pixels"].shape[1:3] != (self.controller.pixels,) * 2:
                raise ControllerError(f"this policy looks at {self.controller.pixels} x {self.controller.pixels} images, "
                                      f"got {one['pixels'].shape[1]} x {one['pixels'].shape[2]}: make the env with "
                                      f"observation_width={self.controller.pixels}, observation_height={self.controller.pixels}")
        world = controller_obs(one, self.obs_type, self.task)
        target, self._carry = self._targets.act(self._carry, world, self._t, self._key)
        self._t += 1
        return gym_pusht_action(target)[0]
