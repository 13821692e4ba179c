"""One scenario, many backends: the scene, the reset, what drives the pusher, and how long it runs."""

from __future__ import annotations

import dataclasses

from mjx_pusht import boundary
from mjx_pusht.errors import ConfigError
from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.task.schedule import Schedule


@dataclasses.dataclass(frozen=True)
class Scenario:
    """What to simulate; every backend takes this and seeds, and returns `Rollouts`.

    With no `controller` the scenario is the chapter's study: the schedule (settle, then
    nudge) commanded every physics step for its total length, no episode termination.
    With one, it is an episode of the task: `episode` says the control rate, the length and
    whether success ends it (see `episode.Episode`).
    """

    scene: SceneSpec = SceneSpec()
    schedule: Schedule = Schedule()
    params: tuple[tuple[str, tuple[float, ...]], ...] = ()  # (name, values) pairs swept as a grid
    reset: str = "chapter"  # reset.RESETS
    controller: object | None = None  # a controllers.Controller
    episode: object | None = None  # an episode.Episode; None with a controller: the defaults
    # {name: (lo, hi)} scale factors drawn per episode from its seed (model/randomize.py); kept as (name, (lo, hi))
    randomize: tuple = ()

    def __post_init__(self) -> None:
        from mjx_pusht.model.params import check_params, means_nothing
        from mjx_pusht.model.randomize import check as check_randomize
        from mjx_pusht.task.episode import Episode
        from mjx_pusht.task.reset import RESETS

        for name, kind in (("scene", SceneSpec), ("schedule", Schedule)):
            if not isinstance(getattr(self, name), kind):
                raise ConfigError(f"Scenario's {name} must be a {kind.__name__}, got {getattr(self, name)!r}")
        # the CLI's --param goes through the same check (model.params.parse_params)
        object.__setattr__(self, "params", check_params(self.params))
        for name, _ in self.params:  # as --randomize refuses them: one rule for both flags
            means_nothing(name, self.scene.variant, "--param (Scenario's params)")
        object.__setattr__(self, "randomize", check_randomize(self.randomize, self.scene))
        if self.params and self.randomize:
            raise ConfigError("a Scenario sweeps a parameter grid or randomises physics per episode, not both")
        boundary.CONTROLLER("Scenario's controller", self.controller)
        if self.episode is not None and not isinstance(self.episode, Episode):
            raise ConfigError(f"Scenario's episode must be an Episode, got {self.episode!r}")
        boundary.OneOf(tuple(RESETS))("reset", self.reset)
        targets = getattr(self.controller, "action_type", None) == "target"
        if self.controller is not None and targets != (self.scene.variant == "gym-pusht"):
            raise ConfigError("the gym-pusht scene's pusher is on position servos: its actions are targets "
                              "(action_type 'target'); the chapter scene's servos take 'velocity' or 'position'")

    def grid(self) -> list[dict[str, float]]:
        """Every parameter combination; a single empty one when nothing is swept."""
        from mjx_pusht.model.params import grid

        return grid({name: list(values) for name, values in self.params})

    def driver(self):
        """(controller, episode) that run this scenario: the chapter's schedule when no controller is given."""
        from mjx_pusht.task.controllers import Nudge
        from mjx_pusht.task.episode import Episode

        if self.controller is None:
            return Nudge(schedule=self.schedule), Episode(frame_skip=1, max_steps=self.schedule.total_steps,
                                                          terminate=False)
        return self.controller, self.episode or Episode()

    @property
    def break_it(self) -> str:
        return self.scene.break_it
