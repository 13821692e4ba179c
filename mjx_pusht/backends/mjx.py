"""The MJX backends: `jax.vmap` over seeds of a `lax.scan` over control steps, compiled once per batch shape.

`impl='jax'` is MJX's own JAX pipeline; it has no (cylinder, box) collision, so it runs the chapter's
scene with a capsule pusher of the same radius and half-length (named in every summary). `impl='warp'` runs
MuJoCo Warp through MJX on the scene as authored, on an NVIDIA GPU or on the CPU. The rollout's body is
`task.episode.control_step`, the same one every backend and the environment run; the weld gap and its peak are
reduced inside the scan, so there is no per-step host round trip and no trajectory unless a trace is asked for.

Jobs live elsewhere: the parameter grid (`grid.ModelGrid`), MJX-Warp's buffers (`warp.Buffers`), laying a
program over devices (`launch`), JAX settings (`jax_setup`), the check of the actions (`actions`), the model MJX
simulates and one world's control step (`mjx_step`, whose names are importable from here, as before).
"""

from __future__ import annotations

import dataclasses
import functools
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from mjx_pusht.api import run_options
from mjx_pusht.backends import actions, launch as launching
from mjx_pusht.backends.base import Backend, BackendError, drawn_params
from mjx_pusht.backends.grid import ModelGrid
from mjx_pusht.backends.jax_setup import enable_compilation_cache
from mjx_pusht.backends.mjx_step import IMPLS, MjxConfig, mjx_model, physics_for, simulated_scene
from mjx_pusht.backends.results import Rollouts, Trace, from_carry
from mjx_pusht.backends.warp import Buffers, dropped, quiet_warp, warp_available
from mjx_pusht.errors import ConfigError
from mjx_pusht.model.layout import QposLayout
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.controllers import seed_key
from mjx_pusht.task.episode import act, begin, control_step
from mjx_pusht.task.reset import start_poses

__all__ = ["MjxBackend", "MjxConfig", "MjxRunner", "Pending", "mjx_model", "simulated_scene"]


class MjxRunner:
    """One put-on-device model (or parameter grid) and its compiled rollouts, one per (batch, trace, buffers)."""

    def __init__(self, scenario: Scenario, cfg: MjxConfig = MjxConfig(), *, devices=None):
        import jax

        if cfg.impl not in IMPLS:
            raise BackendError(f"unknown MJX impl {cfg.impl!r}; choose from {', '.join(IMPLS)}")
        if cfg.impl == "warp" and not warp_available():
            raise BackendError("backend mjx-warp needs warp-lang, which is not installed: pip install 'mjx-pusht[warp]'")
        if cfg.impl == "warp" and (cfg.x64 or jax.config.jax_enable_x64):  # Warp's FFI refuses float64 arrays
            raise ConfigError("MuJoCo Warp computes in float32 only: mjx-warp cannot run in float64 (x64), nor in a "
                              "process where JAX's x64 is already on; use mjx-jax for float64")
        if cfg.x64:
            jax.config.update("jax_enable_x64", True)
        enable_compilation_cache()
        quiet_warp()
        self.scenario, self.cfg = scenario, cfg
        self.scene = simulated_scene(scenario, cfg.impl)
        self.model = mjx_model(self.scene, cfg)
        self.layout = QposLayout.of(self.model)
        # this process's devices: with several processes (distributed.py) each runs its own block of rows
        self.devices = list(devices) if devices else jax.local_devices()
        self.compile_seconds = 0.0
        self._fns: dict = {}
        self._renderers: dict = {}  # kept alive with the programs that call them: Warp frees a renderer's buffers with it
        self.buffers = Buffers(self.model, cfg.contacts_per_world, cfg.constraints_per_world,
                               fixed=cfg.contacts_per_world is not None or cfg.constraints_per_world is not None)
        self.warp_kernels: dict = {}
        if cfg.impl == "warp" and cfg.precompile:
            from mjx_pusht.backends import warp_kernels

            # every kernel the scene needs, compiled on all cores before the first (serial, lazy) launch.
            # Not on a thread beside the model's upload: finding them patches wp.launch process-wide, and
            # a kernel loaded while another thread captures a CUDA graph breaks the capture (measured on
            # 2 x H200: Warp CUDA error 901)
            self.warp_kernels = warp_kernels.precompile(self.model, self.devices)
            self.compile_seconds += self.warp_kernels.get("find_seconds", 0.0) + self.warp_kernels.get("compile_seconds", 0.0)
        self.grid = scenario.grid()
        self.models = ModelGrid(self.model, self.grid, impl=cfg.impl, device=self.devices[0],
                                graph_mode=cfg.graph_mode, randomize=scenario.randomize)
        # x64 is process-wide in JAX: once on, every later runner computes in float64 too
        self.dtype = np.float64 if jax.config.jax_enable_x64 else np.float32

    @property
    def device_name(self) -> str:
        d = self.devices[0]
        return f"{d.platform}:{getattr(d, 'device_kind', d.platform)}" + (f" x{len(self.devices)}" if len(self.devices) > 1 else "")

    def initial_data(self, worlds: int, device=None):
        """A batch's shared mjx.Data template (MJX-Warp's buffers sized for `worlds`)."""
        from mujoco import mjx

        if self.cfg.impl == "warp":
            return self.buffers.make_data(worlds, device)
        return mjx.make_data(self.model, impl="jax", device=device)

    def _build(self, batch: int, trace: bool):
        """Compile the rollout for one batch shape; returns launch(qpos0, key, combo, drawn) -> host arrays.

        A scan over control steps (the controller inside the compiled program, no host round
        trip), each `task.episode.control_step` over `frame_skip` physics steps.
        """
        import jax
        import jax.numpy as jnp

        model, layout, grid = self.model, self.layout, self.models
        controller, episode = self.scenario.driver()
        warp, check, n_dev = self.cfg.impl == "warp", self.cfg.check_actions, len(self.devices)
        fs, settle_step = episode.frame_skip, self.scenario.schedule.settle_steps - 1

        def start(d0, qpos0, key):
            carry = begin(layout, qpos0, key, controller, episode, jnp)
            if check:  # the row's first non-finite action: carried in the scan, read when the chunk is back
                carry = {**carry, "bad_action": actions.record_init((), qpos0.dtype, jnp)}
            qs0 = jnp.zeros((episode.physics_steps, model.nq), qpos0.dtype) if trace else None
            return (d0.replace(qpos=qpos0), jnp.zeros((), jnp.int32), qs0), carry

        def advance(leaves, combo, drawn, key, sim, carry, k, image=None):
            physics = physics_for(grid.row(leaves, combo, drawn), fs, settle_step, layout, warp)
            action, carry = act(carry, sim[0].qpos, k, key, controller, layout, jnp, image)
            if check:
                action, bad = actions.record_update(carry["bad_action"], action, ~carry["ep"]["done"], k, jnp)
                carry = {**carry, "bad_action": bad}
            _, carry, sim = control_step(sim, carry, sim[0].qpos, k, action, controller.action_type, physics,
                                         layout, episode, jnp)
            return sim, carry

        def finish(sim, carry):
            _, ovf, qs = sim
            return carry, ovf, (qs if trace else jnp.zeros((0, model.nq), sim[0].qpos.dtype))

        def one_seed(leaves, d0, qpos0, key, combo, drawn):  # vmapped over the batch: each world's scan
            step = lambda outer, k: (advance(leaves, combo, drawn, key, *outer, k), None)  # noqa: E731
            outer, _ = jax.lax.scan(step, start(d0, qpos0, key), jnp.arange(episode.max_steps))
            return finish(*outer)

        if not controller.pixels:
            batched = jax.vmap(one_seed, in_axes=(None, None, 0, 0, 0, 0))
        else:
            # A controller that looks: MJX-Warp's ray tracer renders the batch each control step. Its call is one
            # for the whole batch (custom_vmap): traced inside a vmapped scan's body it would be traced unbatched
            # first and return every world's image to each, so this rollout scans the vmapped step instead. Where
            # Warp's renderer cannot serve (MJX-JAX; a program a device, since its render context is one GPU's), the
            # raster renderer draws the same bytes in plain JAX ops (render/raster.py), as training's rollouts do.
            if warp and n_dev == 1:
                from mjx_pusht.render.pixels import WarpRenderer

                renderer = WarpRenderer(model, batch, controller.pixels)
            else:
                from mjx_pusht.render.raster import Raster

                renderer = Raster(model, controller.pixels)
            self._renderers[batch] = renderer

            def batched(leaves, d0, qpos0, key, combo, drawn):
                def step(outer, k):
                    image = jax.vmap(renderer)(outer[0][0], outer[1].get("goal"))  # the target at each goal
                    return jax.vmap(advance, in_axes=(None, 0, 0, 0, 0, 0, None, 0))(leaves, combo, drawn, key, *outer,
                                                                                      k, image), None

                outer = jax.vmap(start, in_axes=(None, 0, 0))(d0, qpos0, key)
                outer, _ = jax.lax.scan(step, outer, jnp.arange(episode.max_steps))
                return jax.vmap(finish)(*outer)

        if n_dev > 1 and batch % n_dev:
            raise BackendError(f"a batch of {batch} does not divide over {n_dev} devices")
        per_dev = batch // n_dev
        if n_dev > 1:
            launch, seconds = launching.per_device(batched, self.devices, grid.leaves_on, lambda dev, n: self.initial_data(
                n, dev), per_dev, model.nq, self.dtype, grid.n_drawn)
        else:
            launch, seconds = launching.one_program(batched, self.devices[0], grid.leaves_on(), self.initial_data(
                per_dev, self.devices[0]), batch, model.nq, self.dtype, grid.n_drawn)
        self.compile_seconds += seconds
        return launch

    def run(self, seeds: np.ndarray, *, trace: bool = False, batch: int | None = None, combos=None,
            poses: np.ndarray | None = None) -> Rollouts:
        """Roll out `seeds` (padded up to `batch` so one compiled shape serves every chunk)."""
        return self.collect(self.submit(seeds, trace=trace, batch=batch, combos=combos, poses=poses))

    def submit(self, seeds: np.ndarray, *, trace: bool = False, batch: int | None = None, combos=None,
               poses: np.ndarray | None = None) -> "Pending":
        """Start a rollout on the device thread and return at once; `collect` waits for it and scores it.
        A sweep submits chunk k + 1 before it collects chunk k, so the host's work hides behind the device's."""
        import jax.numpy as jnp

        # the API's arguments get the CLI's checks: [0.5, 1.7] is not seeds 0 and 1, a NaN start no start
        seeds, combos, poses = run_options(self.scenario, seeds, batch, combos, poses)
        n = len(seeds)
        batch = batch or n
        if n > batch:
            raise ConfigError(f"{n} seeds do not fit a batch of {batch}")
        key = (batch, trace, self.buffers.sizes)
        if key not in self._fns:
            self._fns[key] = self._build(batch, trace)
        launch = self._fns[key]
        poses = start_poses(seeds, reset=self.scenario.reset) if poses is None else poses
        qpos0 = self.layout.initial_qpos(self.model, np.concatenate([poses, np.repeat(poses[-1:], batch - n, 0)]))
        rng_key = seed_key(np.concatenate([seeds, np.repeat(seeds[-1:], batch - n)]))
        combos = np.zeros(n, np.int64) if combos is None else np.asarray(combos, np.int64)
        combo = np.concatenate([combos, np.repeat(combos[-1:], batch - n)]).astype(np.int32)
        qpos0 = np.asarray(qpos0, self.dtype)
        drawn = jnp.asarray(self.models.factors(np.concatenate([seeds, np.repeat(seeds[-1:], batch - n)])), self.dtype)
        future = _device_thread().submit(lambda: launch(*map(jnp.asarray, (qpos0, rng_key, combo)), drawn))
        return Pending(seeds, poses, combos, qpos0, batch, trace, future)

    def collect(self, p: "Pending") -> Rollouts:
        """The submitted rollout's rows, checked: dropped contacts grow the buffers and rerun, or fail loudly."""
        import jax

        seeds, poses, combos, n = p.seeds, p.poses, p.combos, len(p.seeds)
        carry, ovf, qs = p.future.result()
        ovf = np.asarray(ovf)[:n]
        if dropped(ovf).any() and self.cfg.impl == "warp" and self.buffers.grow():
            return self.run(seeds, trace=p.trace, batch=p.batch, combos=combos, poses=poses)
        self.buffers.check(ovf)
        trace, qpos0 = p.trace, p.qpos0
        carry = jax.tree.map(lambda a: np.asarray(a)[:n], carry)
        actions.check(carry.pop("bad_action", None), seeds, self.scenario.driver()[0].name)  # padding cut by [:n]
        q0 = np.asarray(qpos0, np.float64)[:n]
        out = from_carry(seeds, poses, self.layout.pusher_xy(q0), carry)
        out.warnings = self.models.warnings[combos]  # MJX raises none of its own; a singular model is still one
        out.params = drawn_params(self.scenario, self.model, seeds, combos)
        if trace:
            out.trace = Trace(np.concatenate([q0[:, None], np.asarray(qs, np.float64)[:n]], axis=1),
                              float(self.model.opt.timestep), self.scenario.driver()[1].frame_skip)
            # the trace and the carried state are two paths to one answer: they must agree
            last = self.layout.tee_pose(out.trace.qpos[:, -1])
            if not np.array_equal(last[out.finite], out.final[out.finite]):
                raise RuntimeError(f"{self.cfg.impl}: the per-step trace disagrees with the carried final state; "
                                   "the trace is not trustworthy on this device")
        return out


@dataclasses.dataclass
class Pending:
    """A submitted rollout: its inputs, and the device thread's future for (carry, overflow bits, trace)."""

    seeds: np.ndarray
    poses: np.ndarray
    combos: np.ndarray
    qpos0: np.ndarray
    batch: int
    trace: bool
    future: object


@functools.lru_cache(maxsize=1)
def _device_thread():
    """One thread launches rollouts, in order: MJX-Warp's program reads its loop predicate on the host, so a
    launch blocks until the device is done; from this thread it blocks nobody else."""
    return ThreadPoolExecutor(max_workers=1, thread_name_prefix="mjx-launch")


class MjxBackend(Backend):
    """MJX with impl='jax' (capsule pusher) or impl='warp' (the scene as authored)."""

    pipelined = True

    def __init__(self, scenario: Scenario, impl: str, *, devices=None, **cfg):
        self.name = f"mjx-{impl}"
        self.runner = MjxRunner(scenario, MjxConfig(impl=impl, **cfg), devices=devices)
        self.model = self.runner.model
        self.scenario = scenario
        self.devices = self.runner.devices
        self.simulated_scene = self.runner.scene  # what MJX simulates (capsule pusher on impl=jax)

    @property
    def impl(self) -> str:
        return self.runner.cfg.impl

    @property
    def device(self) -> str:
        return self.runner.device_name

    @property
    def compile_seconds(self) -> float:
        return self.runner.compile_seconds

    @property
    def buffer_info(self) -> dict | None:
        """MJX-Warp's per-world buffers as they ended, and how often they had to grow."""
        return self.runner.buffers.info() if self.impl == "warp" else None

    @property
    def collisions(self) -> dict:
        """Where this backend's collision functions differ from MuJoCo C's (model/colliders.py has every pair)."""
        if self.impl == "warp":
            return {"box-box": "primitive box_box, as MuJoCo C's mjc_BoxBox (mjDSBL_NATIVECCD set on the MJX model)"
                    if self.runner.cfg.match_c_colliders else "general convex GJK/EPA (MuJoCo C: primitive mjc_BoxBox)",
                    "box-cylinder": "general convex GJK/EPA (MuJoCo C: general convex, native CCD)"}
        return {"box-box": "box_box", "box-capsule": "capsule_convex (the pusher is a capsule here)"}

    @property
    def warp_kernels(self) -> dict | None:
        """MJX-Warp's kernel set-up: modules found and compiled up front, the seconds each took, Warp's banner."""
        if self.impl != "warp":
            return None
        from mjx_pusht.backends.warp import banner

        return {**self.runner.warp_kernels, "warp": banner()}

    @property
    def default_chunk(self) -> int:
        on_gpu = self.devices[0].platform == "gpu"
        # measured on one H100 (benchmarks/results/h100.json): 65,536 worlds is MJX-Warp's fastest
        # batch (19.3 M steps/s), 4,096 its slowest (5.2 M)
        return (65536 if on_gpu else 64) * len(self.devices)

    def run(self, seeds, *, trace: bool = False, batch: int | None = None, combos=None, poses=None) -> Rollouts:
        return self.runner.run(seeds, trace=trace, batch=batch, combos=combos, poses=poses)

    def submit(self, seeds, *, batch: int | None = None, combos=None, poses=None):
        return self.runner.submit(seeds, batch=batch, combos=combos, poses=poses)

    def collect(self, pending) -> Rollouts:
        return self.runner.collect(pending)
