"""`--controller policy:PATH`: a checkpoint written by `mjx-pusht train`, as the training layer's entry in the
task's controller registry (`task.controllers.register`). mjx_pusht registers it when imported; the
checkpoint's reader (policy.py) is imported only when a `policy:` spec is loaded."""

from __future__ import annotations

from mjx_pusht.errors import requires
from mjx_pusht.task.controllers import Controller, ControllerError, register

PREFIX = "policy"


def load_spec(spec: str, *, action_type: str | None = None) -> Controller:
    """`policy:PATH` -> the controller that runs the checkpoint at PATH (velocity actions only)."""
    if action_type not in (None, "velocity"):
        raise ControllerError("a trained policy commands velocities; --action position is for your own controllers")
    with requires("policy:PATH", "train"):  # the checkpoint reader is flax's
        from mjx_pusht.train.policy import load_policy

        return load_policy(spec)


def register_policy() -> None:
    """Make `task.controllers.load` take `policy:PATH`."""
    register(PREFIX, load_spec)
