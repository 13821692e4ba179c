"""Goals: where an episode's target T lies (gym-pusht#17 asks for goals drawn per episode, in the observation).

- `fixed`: the target at the origin with yaw 0 (rules.TARGET_POSE), every episode: every PushT env's goal, and
  this project's default. Nothing of a fixed goal is carried or observed: its episodes are those of before goals.
- `random`: a goal pose drawn per episode from its seed: the goal T's origin uniform over the square of the scene's
  walls shrunk by MARGIN on every side (x, then y, in the walls' own axes), then its yaw uniform in [-pi, pi).
  The draws are `uniform_hash` of the episode's seed key at a step no controller reaches (GOAL_STEP), lanes 0-2:
  counter-based, so every rollout draws its goal where it starts its episode (`episode.begin`), on the host or
  inside a compiled program, the same numbers on every backend (to float32 rounding on MJX, whose state is
  float32), without a goal array handed in. A seed's start is what it always was.

The bounds come from the scene's walls: the chapter's inner faces at +-WORKSPACE_HALF; gym-pusht's at
WALL_INNER_PX in its pixels (model/gym_pusht.py), a square turned by its goal's angle in the world frame. MARGIN
keeps every point of the goal T (T_REACH from its origin) a pusher's width and CLEARANCE from every wall, so the
pusher fits between the T and any wall and can push the T there from any side.

A controller written for the fixed goal follows a random one through `GoalFrame`: it sees the pusher and the T in
the goal's frame (the goal at the origin with yaw 0, as it was written for) and its action is turned back.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from mjx_pusht import boundary
from mjx_pusht.errors import ConfigError
from mjx_pusht.task.controller_base import Controller, Wrapper
from mjx_pusht.task.reset import CLEARANCE, PUSHER_RADIUS
from mjx_pusht.task.rules import T_REACH, WORKSPACE_HALF, array_namespace, keypoints, wrap_angle

GOALS = ("fixed", "random")
GOAL_STEP = 0xFFFFFFFF  # uniform_hash's step counter for the goal's draws: past any episode's control steps
MARGIN = T_REACH + 2 * PUSHER_RADIUS + CLEARANCE  # 0.146 m: from the goal's origin to any wall, at least


def check(goal: str) -> str:
    boundary.OneOf(tuple(GOALS))("goal", goal)  # an array is refused, not compared
    return goal


def region(variant: str) -> tuple[float, ...]:
    """Where a scene variant's random goals lie: (centre x, y, the walls' x axis x, y, their y axis x, y, reach),
    the goal's origin within +-reach of the centre along both axes (module docstring), in metres."""
    if variant == "chapter":
        return (0.0, 0.0, 1.0, 0.0, 0.0, 1.0, WORKSPACE_HALF - MARGIN)
    from mjx_pusht.model import gym_pusht as frame

    lo, hi = frame.WALL_INNER_PX
    mid = (lo + hi) / 2
    centre, ex, ey = frame.to_world(np.array([[mid, mid], [mid + 1, mid], [mid, mid + 1]], np.float64))
    ax, ay = (ex - centre) / frame.PX, (ey - centre) / frame.PX
    return (*centre.tolist(), *ax.tolist(), *ay.tolist(), (hi - lo) / 2 * frame.PX - MARGIN)


def draw(key, area: tuple[float, ...], dtype):
    """(..., 3) goal poses (x, y, yaw) of episodes keyed by `key` (..., 2) uint32 (controllers.seed_key) in
    `area` (`region`), in `dtype`: NumPy or JAX, whichever `key` is."""
    from mjx_pusht.task.controllers import uniform_hash

    xp = array_namespace(key)
    step = xp.asarray(GOAL_STEP, dtype=xp.uint32)  # as uint32: past int32, JAX would not take it as a plain int
    u, v, w = (2 * xp.astype(uniform_hash(key, step, lane), dtype) - 1 for lane in range(3))
    cx, cy, ax, ay, bx, by, reach = area
    return xp.stack([cx + reach * (u * ax + v * bx), cy + reach * (u * ay + v * by), math.pi * w], axis=-1)


def goal_poses(seeds, variant: str) -> np.ndarray:
    """(N, 3) float64 random goal poses for `seeds` on a scene variant: what their episodes draw on the host."""
    from mjx_pusht.task.controllers import seed_key

    return draw(seed_key(seeds), region(variant), np.float64)


def with_goal(obs, goal, obs_type: str):
    """A flat observation with the goal beside the T: `state` (..., 5) gets the goal's pose (x, y, yaw) after it,
    `keypoints` (..., 16) the goal T's 16 after the T's (an env's observation vector, a policy's input)."""
    xp = array_namespace(obs)
    extra = goal if obs_type == "state" else keypoints(goal)
    return xp.concat([obs, xp.astype(extra, obs.dtype)], axis=-1)


def goal_features(obs: dict, obs_type: str):
    """What a goal-conditioned policy reads of its goal (train/policy.features): state: the goal's (x, y), the cosine
    and sine of its yaw, the T's offset from it in its frame, the cosine and sine of the T's yaw from it (8);
    keypoints: the goal T's 8 corners (16). Without obs["goal"], the fixed target's (the origin, yaw 0)."""
    xp = array_namespace(obs["state"])
    s = obs["state"]
    g = xp.astype(obs["goal"], s.dtype) if "goal" in obs else xp.zeros(s.shape[:-1] + (3,), dtype=s.dtype)
    if obs_type == "keypoints":
        return keypoints(g)
    e = to_goal_frame(obs["state"][..., 2:5], g)
    return xp.concat([g[..., 0:2], xp.cos(g[..., 2:3]), xp.sin(g[..., 2:3]), e[..., 0:2], xp.cos(e[..., 2:3]),
                      xp.sin(e[..., 2:3])], axis=-1)


def to_goal_frame(pose, goal):
    """(..., 3) poses (or (..., 2) points) in the frame of (..., 3) goals: the goal at the origin with yaw 0."""
    xp = array_namespace(goal)
    c, s = xp.cos(goal[..., 2:3]), xp.sin(goal[..., 2:3])
    dx, dy = pose[..., 0:1] - goal[..., 0:1], pose[..., 1:2] - goal[..., 1:2]
    xy = xp.concat([c * dx + s * dy, -s * dx + c * dy], axis=-1)
    if pose.shape[-1] == 2:
        return xy
    return xp.concat([xy, wrap_angle(pose[..., 2:3] - goal[..., 2:3])], axis=-1)


def from_goal_frame(xy, goal):
    """(..., 2) points in the goals' frames back to the world frame."""
    xp = array_namespace(goal)
    c, s = xp.cos(goal[..., 2:3]), xp.sin(goal[..., 2:3])
    return xp.concat([c * xy[..., 0:1] - s * xy[..., 1:2] + goal[..., 0:1],
                      s * xy[..., 0:1] + c * xy[..., 1:2] + goal[..., 1:2]], axis=-1)


@dataclasses.dataclass(frozen=True, eq=False)
class GoalFrame(Wrapper):
    """A controller of the fixed goal following obs["goal"]: it acts on the observation seen from the goal's frame,
    and its action is turned (a velocity) or placed (a position or target) back into the world. Without a goal in
    the observation, the controller itself. The walls are where they are: a controller that steers clear of them
    by their world positions misjudges them in the goal's frame (the goal's MARGIN leaves a pusher's room)."""

    reads_goal: ClassVar[bool] = True  # it reads obs["goal"]: wrapped once

    def act(self, carry, obs, t, key):
        if "goal" not in obs:
            return self.inner.act(carry, obs, t, key)
        goal = obs["goal"]
        state = obs["state"]
        xp = array_namespace(state)
        tee = to_goal_frame(state[..., 2:5], goal)
        seen = {**obs, "state": xp.concat([to_goal_frame(state[..., 0:2], goal), tee], axis=-1)}
        seen.pop("goal")
        if "keypoints" in obs:
            seen["keypoints"] = keypoints(tee)
        action, carry = self.inner.act(carry, seen, t, key)
        action = xp.astype(xp.asarray(action), state.dtype)
        if self.inner.action_type == "velocity":
            return from_goal_frame(action, goal * xp.asarray([0.0, 0.0, 1.0], dtype=goal.dtype)), carry
        return from_goal_frame(action, goal), carry


def in_goal_frame(ctrl: Controller) -> Controller:
    return GoalFrame(name=ctrl.name, action_type=ctrl.action_type, inner=ctrl)
