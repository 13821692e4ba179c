"""The controller's base class and its error: what every controller (task/controllers.py) is.

A controller is pure: `act(carry, obs, t, key) -> (action, carry)` (task/controllers.py says more). The base
lives apart from the built-ins so that a built-in in a module of its own (task/expert_gym_pusht.py) can
subclass it while controllers.py lists it among the built-ins, with no import loop.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.task.rules import ACTION_TYPES, array_namespace


class ControllerError(MjxPushtError, ValueError):
    """A controller cannot be found, loaded or used; the message says why."""


@dataclasses.dataclass(frozen=True)
class Controller:
    """The base: stateless, zero action. Subclasses override `act` (and `init` to keep state)."""

    name: str = "zero"
    action_type: str = "velocity"
    # The side of the top-camera image the controller looks at, in obs["pixels"] (each backend renders it for
    # every control step; render/pixels.py); 0: it reads the state alone, and nothing is rendered.
    pixels: ClassVar[int] = 0
    # Whether it pushes toward obs["goal"] (random goals, task/goals.py) itself; if not, it runs on random goals
    # seeing the scene from each goal's frame (task/goals.GoalFrame).
    reads_goal: ClassVar[bool] = False

    def __post_init__(self) -> None:
        if self.action_type not in ACTION_TYPES:
            raise ControllerError(f"unknown action type {self.action_type!r}; choose from {', '.join(ACTION_TYPES)}")

    def init(self, key):
        xp = array_namespace(key)
        return xp.zeros(key.shape[:-1], dtype=xp.int32)

    def act(self, carry, obs, t, key):
        xp = array_namespace(obs["state"])
        return xp.zeros(obs["state"].shape[:-1] + (2,), dtype=obs["state"].dtype), carry

    def open_loop(self, steps: int, frame_skip: int) -> np.ndarray | None:
        """(steps, 2) velocity commands when the action ignores the observation; None for feedback."""
        return None


@dataclasses.dataclass(frozen=True, eq=False)
class Wrapper(Controller):
    """A controller around another (`inner`): what it looks at, whether it reads the goal, and its state at reset
    are the inner one's; a subclass changes only what its `act` makes of the inner action or observation."""

    inner: Controller | None = None

    @property
    def pixels(self) -> int:
        return self.inner.pixels

    @property
    def reads_goal(self) -> bool:
        return self.inner.reads_goal

    def init(self, key):
        return self.inner.init(key)
