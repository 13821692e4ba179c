"""The schedule: settle with zero control, then nudge the pusher north."""

from __future__ import annotations

import dataclasses

import numpy as np

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
        if self.settle_steps < 1:
            raise ConfigError(f"settle steps must be positive, got {self.settle_steps}")
        if self.nudge_steps < 1:
            raise ConfigError(f"nudge steps must be positive, got {self.nudge_steps}")

    @property
    def total_steps(self) -> int:
        return self.settle_steps + self.nudge_steps

    def controls(self) -> np.ndarray:
        """(total_steps, nu) velocity targets, step by step."""
        ctrl = np.zeros((self.total_steps, len(self.nudge_ctrl)))
        ctrl[self.settle_steps :] = self.nudge_ctrl
        return ctrl
