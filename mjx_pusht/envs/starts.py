"""reset_to_state in the world frame: [tee x, y, yaw, pusher x, y] in metres and radians, its bounds and the
pusher clear of the T. The one rule every entry point that takes a start checks (the functional env, the
gymnasium envs, the Brax adapter)."""

from __future__ import annotations

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.task.reset import PUSHER_RADIUS
from mjx_pusht.task.rules import WORKSPACE_HALF, distance_to_tee

# reset_to_state [tee x, y, yaw, pusher x, y] in metres: both positions inside the walls (yaw unbounded)
START_LO = np.array([-WORKSPACE_HALF, -WORKSPACE_HALF, np.nan, -WORKSPACE_HALF, -WORKSPACE_HALF])
START_HI = -START_LO


def clear_of_tee(starts: np.ndarray, variant: str) -> np.ndarray:
    """reset_to_state's pusher must not overlap the T: MuJoCo would fling them apart on the first step. The
    gym-pusht variant takes overlaps, as gym-pusht does (its own random resets make them)."""
    if variant == "chapter" and starts.shape[1] == 5:
        inside = distance_to_tee(starts[:, 3:5], starts[:, 0:3]) < PUSHER_RADIUS
        if inside.any():
            r = np.flatnonzero(inside)
            raise ConfigError(f"reset_to_state puts the pusher (radius {PUSHER_RADIUS} m) inside the T in row(s) "
                              f"{', '.join(map(str, r[:8]))}: {starts[r[0]].tolist()}")
    return starts



def episode_with_goal(episode, goal: str, variant: str):
    """The functional env's episodes with its goal option (task/goals.GOALS): random goals drawn in the variant's
    walls (pixels draw each episode's target at its goal: render/pixels.py `Target`)."""
    import dataclasses

    from mjx_pusht.task.goals import check, region

    if check(goal) == "fixed":
        return episode
    return dataclasses.replace(episode, goal=region(variant))
