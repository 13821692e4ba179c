"""`make_backend`: a backend by name, built from its implementation (cpu.py, mjx.py). It sits above them:
the protocol (base.py) knows no implementation, and each implementation knows only the protocol."""

from __future__ import annotations

from mjx_pusht.backends.base import IMPL, Backend, resolve


def make_backend(name: str, scenario, **kwargs) -> Backend:
    """Build a backend by name (`auto` is resolved first); MJX keyword options pass through."""
    name, _ = resolve(name)
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
