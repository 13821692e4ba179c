"""gym-pusht's observation in, gym-pusht's action out: the one door between gym-pusht 0.1.8 and every controller.

A user's plain gym-pusht loop (`GymPushtPolicy`, train/gym_pusht_policy.py) and `eval --backend gym-pusht`
(backends/gym_pusht.py) both pass what gym-pusht's `reset`/`step` return through `controller_obs` and the
controller's target through `gym_pusht_action`, so an eval there is, episode for episode, the loop a user runs.
Nothing here reads pymunk's bodies: gym-pusht's `state` observation is agent x, y, block x, y and the block's
angle wrapped to [0, 2 pi) (its `_get_obs`); `pixels_agent_pos` is the image and the agent's x, y. The yaw a
controller is handed lies in the task's window (task/tasks.py `Task.observed`), whatever gym-pusht's wrap.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.rules import observe
from mjx_pusht.task.tasks import TASKS

FRAME_PX = 512.0  # gym-pusht's action space: targets in its 512-pixel frame


def controller_obs(obs, obs_type: str, task: str = "gym-pusht") -> dict:
    """gym-pusht observations, a batch (state: (N, 5); pixels_agent_pos: {"pixels": (N, H, W, 3) uint8,
    "agent_pos": (N, 2)}), as the observation dict a controller acts on: `state` (pusher x, y, tee x, y, yaw; world
    frame, metres, the yaw in `task`'s window), `keypoints`, and `pixels` for a pixel observation. A pixel
    observation carries no pose of the T (gym-pusht gives none): its state's tee is zeros, read by no pixel policy."""
    if obs_type == "state":
        s = np.asarray(obs, np.float64)
        agent, tee = s[:, 0:2], frame.pose_to_world(s[:, 2:4], s[:, 4])
    else:
        agent = np.asarray(obs["agent_pos"], np.float64)
        tee = np.zeros((len(agent), 3))
    world = observe(frame.to_world(agent), tee)
    world["state"] = TASKS[task].observed(world["state"])
    if obs_type != "state":
        world["pixels"] = np.asarray(obs["pixels"], np.uint8)
    return world


def gym_pusht_action(target) -> np.ndarray:
    """World targets (N, 2), metres, as gym-pusht's actions: pixels in its frame, float32 (its action space's dtype)."""
    return np.clip(frame.to_px(np.asarray(target, np.float64)), 0.0, FRAME_PX).astype(np.float32)
