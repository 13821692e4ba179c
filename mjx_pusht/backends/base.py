"""What a backend is: a scenario and seeds in, per-seed `Rollouts` out (Brax's `envs/base.py` in spirit).

Everything downstream (tables, summaries, recordings, comparison, benchmarks) holds a
`Backend` and reads `Rollouts`; it never asks which backend made them, and never probes one
for what it offers: every backend has every member below. The implementations (cpu.py, mjx.py) import
this module, never the other way; `factory.make_backend` builds one by name.
"""

from __future__ import annotations

import functools
import importlib.metadata
import platform

from mjx_pusht.api import keyword_checked
from mjx_pusht.backends.results import Rollouts
from mjx_pusht.errors import MjxPushtError

BACKENDS = ("auto", "cpu", "mjx-jax", "mjx-warp", "gym-pusht")  # gym-pusht: the peer itself, its task's episodes only
IMPL = {"mjx-jax": "jax", "mjx-warp": "warp"}  # MJX backend name -> mjx.put_model's impl


class BackendError(MjxPushtError, RuntimeError):
    """A backend cannot run here (missing package, no device, unknown name); the message says why."""


class Backend:
    """The interface. Subclasses set `name`, `scenario`, `model`, `devices`, `simulated_scene` and implement
    `submit`/`collect`; `run` is the two back to back. Synchronous backends finish in `submit`."""

    name: str
    scenario: object  # the Scenario asked for
    simulated_scene: object  # the SceneSpec actually stepped (MJX-JAX substitutes a capsule pusher)
    model: object  # the compiled MjModel
    devices: list  # this process's devices the rollouts spread over
    compile_seconds: float = 0.0
    default_chunk: int = 16384
    buffer_info: dict | None = None  # MJX-Warp's buffers and growths
    warp_kernels: dict | None = None  # MJX-Warp's kernel set-up
    collisions: dict = {}  # collision functions per pair kind, for the summary
    # True: `submit` returns at once and the device works while the host does (a sweep keeps two chunks in
    # flight); False: the work happens in `collect`
    pipelined: bool = False

    def __init_subclass__(cls, **kwargs):
        """Each backend's public methods (`run`, `submit`, `close`, ...) bind their arguments at the door
        (`api.keyword_checked`): `run(bogus=1)` or `run()` is one line naming what they take, not Python's TypeError."""
        super().__init_subclass__(**kwargs)
        keyword_checked(cls)

    @property
    def pusher(self) -> str:
        return self.simulated_scene.pusher

    @property
    def device(self) -> str:
        return str(self.devices[0])

    def run(self, seeds, *, trace: bool = False, batch: int | None = None, combos=None, poses=None) -> Rollouts:
        """A row per entry of `seeds`, in order: a seed given twice is rolled out twice, and its rows are the same
        bits (a determinism check; the CLI's tables are keyed by seed, so `--seeds` refuses a repeat)."""
        raise NotImplementedError

    def submit(self, seeds, *, batch: int | None = None, combos=None, poses=None):
        """Start rolling out `seeds`; returns a handle for `collect`. Here: the work is deferred to `collect`."""
        return functools.partial(self.run, seeds, batch=batch, combos=combos, poses=poses)

    def collect(self, pending) -> Rollouts:
        return pending()

    def describe(self) -> dict:
        """What a summary records about the backend that made its rows."""
        return {"backend": self.name, "device": self.device, "pusher_shape": self.pusher,
                "warp_buffers": self.buffer_info, "warp_kernels": self.warp_kernels,
                "collision_functions": self.collisions}

    def close(self) -> None:
        """Release worker processes and the like (nothing for most backends)."""


keyword_checked(Backend)  # its own public methods too (collect, describe): __init_subclass__ wraps a subclass's


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("mujoco", "mujoco-mjx", "jax", "jaxlib", "warp-lang", "numpy"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            pass
    return out


def has_gpu() -> bool:
    try:
        import jax

        return any(d.platform == "gpu" for d in jax.devices())
    except RuntimeError:
        return False


def resolve(name: str) -> tuple[str, str]:
    """The concrete backend `name` means here, and why (for `auto`)."""
    if not isinstance(name, str) or name not in BACKENDS:  # (an array's `in` is no answer)
        raise BackendError(f"unknown backend {' '.join(repr(name).split())[:60]}; choose from {', '.join(BACKENDS)}")
    if name != "auto":
        return name, "asked for"
    from mjx_pusht.backends.warp import warp_available

    if has_gpu():
        if warp_available():
            return "mjx-warp", "auto: a GPU is present and MJX-Warp runs the scene as authored"
        return "cpu", "auto: a GPU is present but warp-lang is not; mjx-jax would change the pusher shape, so cpu"
    return "cpu", "auto: no GPU here; MuJoCo C on every core is the fastest faithful path"


def drawn_params(scenario, model, seeds, combos) -> dict | None:
    """Each row's parameter values, for the per-seed table's param_ columns: its grid combination's, or the
    physics drawn from its seed (model/randomize.py, as the parameters' own values); None when neither."""
    import numpy as np

    if scenario.randomize:
        from mjx_pusht.model.randomize import factors, values

        return values(model, scenario.randomize, factors(scenario.randomize, seeds))
    if scenario.params:
        grid = scenario.grid()
        return {name: np.array([grid[c][name] for c in combos]) for name, _ in scenario.params}
    return None
