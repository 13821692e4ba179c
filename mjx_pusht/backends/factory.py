"""`make_backend`: a backend by name, built from its implementation (cpu.py, mjx.py). It sits above them:
the protocol (base.py) knows no implementation, and each implementation knows only the protocol."""

from __future__ import annotations

from mjx_pusht import boundary, validate
from mjx_pusht.backends.base import IMPL, Backend, resolve
from mjx_pusht.errors import ConfigError
from mjx_pusht.scenario import Scenario


def make_backend(name: str, scenario, **kwargs) -> Backend:
    """Build a backend by name (`auto` is resolved first); MJX keyword options pass through."""
    name, _ = resolve(name)
    if not isinstance(scenario, Scenario):
        raise ConfigError(f"make_backend takes a Scenario, got {type(scenario).__name__}")
    kwargs = boundary.check(boundary.BACKEND_OPTIONS[name], kwargs, f"make_backend({name!r})")
    # a backend's rollout runs max_steps control steps in one call (a scan on MJX, a control table on the CPU): the
    # CLI's --max-steps bound. An env's own episode may be longer (it steps one control step a call).
    # (A schedule's steps are bounded by Schedule itself.)
    if scenario.controller is not None:
        episode = scenario.driver()[1]
        validate.steps("episode max_steps", episode.max_steps)
        if episode.physics_steps > validate.MAX_PHYSICS_STEPS:
            raise ConfigError(f"an episode of {episode.max_steps:,} control steps x {episode.frame_skip:,} physics "
                              f"steps each is {episode.physics_steps:,} physics steps, more than the "
                              f"{validate.MAX_PHYSICS_STEPS:,} a rollout runs (10,000 s at 100 Hz): fewer --max-steps "
                              "or a smaller --frame-skip")
    if name == "cpu":
        from mjx_pusht.backends.cpu import CpuBackend

        return CpuBackend(scenario, nthread=kwargs.get("nthread"), workers=kwargs.get("workers", 1))
    if name == "gym-pusht":
        from mjx_pusht.backends.gym_pusht import GymPushtBackend

        return GymPushtBackend(scenario)
    from mjx_pusht.backends.mjx import MjxBackend

    kwargs.pop("nthread", None)
    kwargs.pop("workers", None)  # CPU processes: the MJX backends batch on their device instead
    return MjxBackend(scenario, IMPL[name], **kwargs)
