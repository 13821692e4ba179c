"""One scenario, many backends: the scene, the schedule and the seeds' start poses."""

from __future__ import annotations

import dataclasses

from mjx_pusht.schedule import Schedule
from mjx_pusht.scene import SceneSpec


@dataclasses.dataclass(frozen=True)
class Scenario:
    """What to simulate; every backend takes this and seeds, and returns `Rollouts`."""

    scene: SceneSpec = SceneSpec()
    schedule: Schedule = Schedule()
    params: tuple[tuple[str, tuple[float, ...]], ...] = ()  # (name, values) pairs swept as a grid

    def grid(self) -> list[dict[str, float]]:
        """Every parameter combination; a single empty one when nothing is swept."""
        from mjx_pusht.params import grid

        return grid({name: list(values) for name, values in self.params})

    @property
    def break_it(self) -> str:
        return self.scene.break_it
