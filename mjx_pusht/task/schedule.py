"""The schedule: settle with zero control, then nudge the pusher north."""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht import validate
from mjx_pusht.errors import ConfigError

SETTLE_STEPS = 40
DEFAULT_NUDGE_STEPS = 120
SMOKE_NUDGE_STEPS = 120  # fixed under --smoke so CI can diff two runs byte for byte


@dataclasses.dataclass(frozen=True)
class Schedule:
    """Open-loop controls: `settle_steps` at ctrl 0, then `nudge_steps` at `nudge_ctrl` (m/s)."""

    settle_steps: int = SETTLE_STEPS
    nudge_steps: int = DEFAULT_NUDGE_STEPS
    nudge_ctrl: tuple[float, float] = (0.0, 1.0)

    def __post_init__(self) -> None:
        validate.steps("settle_steps", self.settle_steps)
        validate.steps("nudge_steps", self.nudge_steps)
        ctrl = self.nudge_ctrl
        if isinstance(ctrl, (str, bytes)) or not hasattr(ctrl, "__len__") or len(ctrl) != 2:
            raise ConfigError(f"nudge_ctrl is the pusher's (x, y) velocity target, two numbers; got {ctrl!r}")
        # the servos' ctrlrange clips a target to +-1 m/s; a NaN or inf target is no velocity at all
        for v in ctrl:
            validate.real_range("nudge_ctrl", v, -1e10, 1e10)

    @property
    def total_steps(self) -> int:
        return self.settle_steps + self.nudge_steps

    def controls(self) -> np.ndarray:
        """(total_steps, nu) velocity targets, step by step."""
        ctrl = np.zeros((self.total_steps, len(self.nudge_ctrl)))
        ctrl[self.settle_steps :] = self.nudge_ctrl
        return ctrl
