"""Backends behind one interface: a scenario and seeds in, per-seed `Rollouts` out.

Everything downstream (tables, summaries, recordings, comparison, benchmarks)
reads `Rollouts` and never needs to know which backend made them.
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import platform

import numpy as np

from mjx_pusht.backends.results import Rollouts
from mjx_pusht.scenario import Scenario

BACKENDS = ("auto", "cpu", "mjx-jax", "mjx-warp")


class BackendError(RuntimeError):
    """A backend cannot run here (missing package, no device); the message says why."""


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("mujoco", "mujoco-mjx", "jax", "jaxlib", "warp-lang", "numpy"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            pass
    return out


@dataclasses.dataclass
class CpuBackend:
    """MuJoCo C, float64, every core: the determinism reference."""

    scenario: Scenario
    nthread: int | None = None
    name: str = "cpu"
    compile_seconds: float = 0.0
    default_chunk: int = 16384
    # processes for feedback controllers (see rollout_cpu.FeedbackPool); 1: this process only
    workers: int = 1

    def __post_init__(self) -> None:
        from mjx_pusht.backends.cpu import _model, default_threads

        self.nthread = self.nthread or default_threads()
        self.model = _model(self.scenario)
        self._pool = None

    @property
    def pusher(self) -> str:
        return self.scenario.scene.pusher

    @property
    def device(self) -> str:
        return f"cpu ({self.nthread} threads)"

    collisions = {"box-box": "mjc_BoxBox (primitive)", "box-cylinder": "mjc_Convex (native CCD)"}

    def run(self, seeds: np.ndarray, *, trace: bool = False, batch: int | None = None, combos=None,
            poses=None) -> Rollouts:
        from mjx_pusht.backends.cpu import FeedbackPool, run_cpu

        controller, episode = self.scenario.driver()
        feedback = controller.open_loop(episode.max_steps, episode.frame_skip) is None
        if feedback and self.workers > 1 and not trace and len(seeds) >= 2 * self.workers:
            if self._pool is None:
                self._pool = FeedbackPool(self.workers)
            return self._pool.run(self.scenario, seeds, combos=combos, poses=poses)
        return run_cpu(self.scenario, seeds, trace=trace, nthread=self.nthread, model=self.model, combos=combos,
                       poses=poses)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None


class MjxBackend:
    """MJX with impl='jax' (capsule pusher) or impl='warp' (the scene as authored)."""

    def __init__(self, scenario: Scenario, impl: str, *, devices=None, **cfg):
        from mjx_pusht.backends.mjx import MjxConfig, MjxRunner, warp_available

        if impl == "warp" and not warp_available():
            raise BackendError("backend mjx-warp needs warp-lang, which is not installed: pip install 'mujoco-mjx[warp]'")
        self.name = f"mjx-{impl}"
        self.runner = MjxRunner(scenario, MjxConfig(impl=impl, **cfg), devices=devices)
        self.model = self.runner.model
        self.scenario = scenario

    @property
    def pusher(self) -> str:
        return self.runner.scene.pusher

    @property
    def device(self) -> str:
        return self.runner.device_name

    @property
    def compile_seconds(self) -> float:
        return self.runner.compile_seconds

    @property
    def buffer_info(self) -> dict | None:
        """MJX-Warp's per-world buffers as they ended, and how often they had to grow."""
        if self.runner.cfg.impl != "warp":
            return None
        c, r = self.runner.buffers
        return {"contacts_per_world": c, "rows_per_world": r, "growths": self.runner.growths}

    @property
    def collisions(self) -> dict:
        """Where this backend's collision functions differ from MuJoCo C's (colliders.py has every pair)."""
        if self.runner.cfg.impl == "warp":
            matched = self.runner.cfg.match_c_colliders
            return {"box-box": "primitive box_box, as MuJoCo C's mjc_BoxBox (mjDSBL_NATIVECCD set on the MJX model)"
                    if matched else "general convex GJK/EPA (MuJoCo C: primitive mjc_BoxBox)",
                    "box-cylinder": "general convex GJK/EPA (MuJoCo C: general convex, native CCD)"}
        return {"box-box": "box_box", "box-capsule": "capsule_convex (the pusher is a capsule here)"}

    @property
    def warp_kernels(self) -> dict | None:
        """MJX-Warp's kernel set-up: modules found and compiled up front, and the seconds each took."""
        return self.runner.warp_kernels or None

    @property
    def default_chunk(self) -> int:
        on_gpu = self.runner.devices[0].platform == "gpu"
        # measured on one H100 (benchmarks/results/h100.json, history/h100-tuning/h100-batches.json):
        # 65,536 worlds is MJX-Warp's fastest batch (19.3 M steps/s), 4,096 its slowest (5.2 M)
        per = 65536 if on_gpu else 64
        return per * len(self.runner.devices)

    def run(self, seeds: np.ndarray, *, trace: bool = False, batch: int | None = None, combos=None,
            poses=None) -> Rollouts:
        return self.runner.run(seeds, trace=trace, batch=batch, combos=combos, poses=poses)

    def submit(self, seeds: np.ndarray, *, batch: int | None = None, combos=None, poses=None):
        """Start a rollout and return at once (the device works while the host does); `collect` finishes it."""
        return self.runner.submit(seeds, batch=batch, combos=combos, poses=poses)

    def collect(self, pending) -> Rollouts:
        return self.runner.collect(pending)


def has_gpu() -> bool:
    try:
        import jax

        return any(d.platform == "gpu" for d in jax.devices())
    except RuntimeError:
        return False


def resolve(name: str) -> tuple[str, str]:
    """The concrete backend `name` means here, and why (for `auto`)."""
    if name not in BACKENDS:
        raise BackendError(f"unknown backend {name!r}; choose from {', '.join(BACKENDS)}")
    if name != "auto":
        return name, "asked for"
    from mjx_pusht.backends.mjx import warp_available

    if has_gpu():
        if warp_available():
            return "mjx-warp", "auto: a GPU is present and MJX-Warp runs the scene as authored"
        return "cpu", "auto: a GPU is present but warp-lang is not; mjx-jax would change the pusher shape, so cpu"
    return "cpu", "auto: no GPU here; MuJoCo C on every core is the fastest faithful path"


def make_backend(name: str, scenario: Scenario, **kwargs):
    """Build a backend by name (after `resolve`); MJX keyword options pass through."""
    if name == "cpu":
        return CpuBackend(scenario, nthread=kwargs.get("nthread"), workers=kwargs.get("workers", 1))
    if name in ("mjx-jax", "mjx-warp"):
        kwargs.pop("nthread", None)
        kwargs.pop("workers", None)  # CPU processes: the MJX backends batch on their device instead
        return MjxBackend(scenario, name.split("-")[1], **kwargs)
    raise BackendError(f"unknown backend {name!r}; choose from {', '.join(BACKENDS)}")
