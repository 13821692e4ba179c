"""Goals: where an episode's target T lies (gym-pusht#17 asks for goals drawn per episode, in the observation).

- `fixed`: the target at the origin with yaw 0 (rules.TARGET_POSE), every episode: every PushT env's goal, and
  this project's default. Nothing of a fixed goal is carried or observed: its episodes are those of before goals.
- `random`: a goal pose drawn per episode from its seed, by its own generator, `default_rng([seed, GOAL_STREAM])`
  (the start keeps `default_rng(seed)`, so a seed starts where it always did): the goal T's origin uniform over
  the square of the scene's walls shrunk by MARGIN on every side (drawn in the walls' own axes: x, then y), then
  its yaw uniform in [-pi, pi). The same draw on every backend: it is made on the host, as the starts are.

The bounds come from the scene's walls: the chapter's inner faces at +-WORKSPACE_HALF; gym-pusht's at
WALL_INNER_PX in its pixels (model/gym_pusht.py), a square turned by its goal's angle in the world frame. MARGIN
keeps every point of the goal T (T_REACH from its origin) a pusher's width and CLEARANCE from every wall, so the
pusher fits between the T and any wall and can push the T there from any side.

A controller written for the fixed goal follows a random one through `GoalFrame`: it sees the pusher and the T in
the goal's frame (the goal at the origin with yaw 0, as it was written for) and its action is turned back.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.task.controller_base import Controller
from mjx_pusht.task.reset import CLEARANCE, PUSHER_RADIUS
from mjx_pusht.task.rules import T_REACH, WORKSPACE_HALF, array_namespace, keypoints, wrap_angle

GOALS = ("fixed", "random")
GOAL_STREAM = 0x60A1  # the goal generator's second word: default_rng([seed, GOAL_STREAM])
MARGIN = T_REACH + 2 * PUSHER_RADIUS + CLEARANCE  # 0.146 m: from the goal's origin to any wall, at least


def check(goal: str) -> str:
    if goal not in GOALS:
        raise ConfigError(f"unknown goal {goal!r}; choose from {', '.join(GOALS)}")
    return goal


def arena(variant: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The walled square of a scene variant in the world frame: its centre (2,), its axes (2, 2) (rows: the unit x
    and y of the walls' own frame) and its inner half-width, in metres."""
    if variant == "chapter":
        return np.zeros(2), np.eye(2), WORKSPACE_HALF
    from mjx_pusht.model import gym_pusht as frame

    lo, hi = frame.WALL_INNER_PX
    mid = (lo + hi) / 2
    centre, ex, ey = frame.to_world(np.array([[mid, mid], [mid + 1, mid], [mid, mid + 1]], np.float64))
    axes = np.stack([ex - centre, ey - centre]) / frame.PX
    return centre, axes, (hi - lo) / 2 * frame.PX


def goal_poses(seeds, variant: str) -> np.ndarray:
    """(N, 3) random goal poses (x, y, yaw) for `seeds` on a scene variant (module docstring)."""
    centre, axes, half = arena(variant)
    reach = half - MARGIN
    out = np.empty((len(seeds), 3))
    for i, seed in enumerate(np.asarray(seeds, np.int64).reshape(-1).tolist()):
        rng = np.random.default_rng([seed, GOAL_STREAM])
        u, v = rng.uniform(-reach, reach), rng.uniform(-reach, reach)
        out[i] = (*(centre + u * axes[0] + v * axes[1]), rng.uniform(-np.pi, np.pi))
    return out


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
class GoalFrame(Controller):
    """A controller of the fixed goal following obs["goal"]: it acts on the observation seen from the goal's frame,
    and its action is turned (a velocity) or placed (a position or target) back into the world. Without a goal in
    the observation, the controller itself. The walls are where they are: a controller that steers clear of them
    by their world positions misjudges them in the goal's frame (the goal's MARGIN leaves a pusher's room)."""

    inner: Controller | None = None

    @property
    def pixels(self) -> int:
        return self.inner.pixels

    def init(self, key):
        return self.inner.init(key)

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
