"""The MJX backends: `jax.vmap` over seeds of a `lax.scan` over steps, jit-compiled once per batch shape.

`impl='jax'` is MJX's own JAX pipeline; it has no (cylinder, box) collision, so it
runs the scene with a capsule pusher of the same radius and half-length (named in
every summary). `impl='warp'` runs MuJoCo Warp through MJX on the scene as
authored, on an NVIDIA GPU or on the CPU through Warp.

The weld gap and its peak are reduced inside the scan: no per-step host round
trip and no trajectory kept unless a trace is asked for.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import mujoco
import numpy as np

from mjx_pusht.task.controllers import seed_key
from mjx_pusht.task.episode import after_control_step, after_physics_step, begin, decide
from mjx_pusht.task.reset import QposLayout, start_poses
from mjx_pusht.backends.results import Rollouts, Trace, from_carry
from mjx_pusht.scenario import Scenario
from mjx_pusht.model.scene import SceneSpec, build_model

IMPLS = ("jax", "warp")
PUSHER_FOR_IMPL = {"jax": "capsule", "warp": "cylinder"}

# Warp overflow bits that mean something was dropped (contacts, constraint rows),
# as opposed to the solver merely reaching its iteration limit.
_DROP_BITS = (1 << 0) | (1 << 1) | (1 << 2) | (1 << 3) | (1 << 4) | (1 << 7) | (1 << 8)
_MAX_CONTACTS_PER_PAIR = 8  # box-box, the richest pair in this scene, makes at most 8


class BufferOverflow(RuntimeError):
    """MJX-Warp ran out of contact or constraint buffer: contacts were dropped."""


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache so a second process does not compile again."""
    import jax

    cache = Path(path or os.environ.get("MJX_PUSHT_JAX_CACHE") or Path.home() / ".cache" / "mjx_pusht" / "jax")
    cache.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return cache


def warp_available() -> bool:
    try:
        import warp  # noqa: F401
    except ImportError:
        return False
    return True


def collision_pairs(model: mujoco.MjModel) -> list[tuple[str, str]]:
    """Geom pairs the collision filter lets touch: different bodies, not both static, masks overlap."""
    pairs = []
    for i in range(model.ngeom):
        for j in range(i + 1, model.ngeom):
            bi, bj = int(model.geom_bodyid[i]), int(model.geom_bodyid[j])
            if bi == bj or (model.body_weldid[bi] == 0 and model.body_weldid[bj] == 0):
                continue
            if not (model.geom_contype[i] & model.geom_conaffinity[j] or model.geom_contype[j] & model.geom_conaffinity[i]):
                continue
            pairs.append((model.geom(i).name, model.geom(j).name))
    return pairs


def contacts_per_world(model: mujoco.MjModel) -> int:
    """An upper bound on simultaneous contacts in one world, from the scene's geometry."""
    return len(collision_pairs(model)) * _MAX_CONTACTS_PER_PAIR


def constraints_per_world(model: mujoco.MjModel, contacts: int | None = None) -> int:
    """Rows: pyramidal friction gives 2*(condim-1) rows a contact, plus one per frictionloss DOF."""
    condim = int(model.geom_condim.max())
    contacts = contacts_per_world(model) if contacts is None else contacts
    return contacts * max(1, 2 * (condim - 1)) + int(model.nv)


# Where MJX-Warp's buffers start: the CPU never sees more than 8 contacts (27 rows) in one
# world of this scene, and naconmax is shared by all worlds of a batch. A chunk that
# overflows is rerun with doubled buffers, up to the geometric bounds above, so a
# tight start costs nothing in correctness.
START_CONTACTS_PER_WORLD = 16
START_ROWS_PER_WORLD = 48


@dataclasses.dataclass(frozen=True)
class MjxConfig:
    """How MJX runs: implementation, precision and solver settings (None: the scene's own)."""

    impl: str = "jax"
    x64: bool = False
    iterations: int | None = None
    ls_iterations: int | None = None
    tolerance: float | None = None
    # MJX-Warp buffers per world; None: start at the typical need and grow on overflow
    contacts_per_world: int | None = None
    constraints_per_world: int | None = None
    # MJX-Warp only: who captures the CUDA graph, a warp.JaxCallableGraphMode name; None: MJX's default
    graph_mode: str | None = None
    # MJX-Warp only: compile the scene's kernels on all cores up front (False: lazily, one by one)
    precompile: bool = True
    # MJX-Warp only: collide box with box through MuJoCo Warp's primitive box_box, as MuJoCo C does
    # (mjc_BoxBox), by setting mjDSBL_NATIVECCD on the model MJX receives; see colliders.py
    match_c_colliders: bool = True


def simulated_scene(scenario: Scenario, impl: str) -> SceneSpec:
    """The scene an impl actually runs: the jax impl substitutes the capsule pusher."""
    return dataclasses.replace(scenario.scene, pusher=PUSHER_FOR_IMPL[impl])


def _mj_model(scene: SceneSpec, cfg: MjxConfig) -> mujoco.MjModel:
    model = build_model(scene)
    # MJX never resets a diverged world (NaN simply propagates into the finite
    # flag), and MuJoCo Warp refuses the flag outright, so clear it here.
    model.opt.disableflags &= ~int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
    if cfg.impl == "warp" and cfg.match_c_colliders:
        # MuJoCo Warp sends box-box to GJK/EPA unless this bit is set; MuJoCo C always uses its
        # primitive mjc_BoxBox (its contacts are the same with the bit on or off: colliders.py)
        model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)
    if cfg.iterations is not None:
        model.opt.iterations = cfg.iterations
    if cfg.ls_iterations is not None:
        model.opt.ls_iterations = cfg.ls_iterations
    if cfg.tolerance is not None:
        model.opt.tolerance = cfg.tolerance
    return model


def advance(mx, d, carry, u, k, frame_skip: int, settle_step: int, layout, warp: bool, ovf, qs=None):
    """One control step of one world: `frame_skip` mjx.steps at ctrl u, each folded into the invariants.

    `ovf` accumulates MJX-Warp's overflow bits; `qs`, when given, records qpos after every
    physics step (the trace).
    """
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    def physics_step(inner, j):
        d, carry, ovf, qs = inner
        t = k * frame_skip + j
        d = mjx.step(mx, d.replace(ctrl=u))
        carry = after_physics_step(carry, t, settle_step, layout, d.qpos, d.qvel, d.sensordata, jnp)
        if warp:
            ovf = ovf | d._impl.overflow
        if qs is not None:
            # Written into the carry, not stacked as scan output: under MJX-Warp's CUDA-graph
            # capture on an H100 the stacked per-step qpos came back stale (frame 1 read as
            # qpos0) while the carried state was right.
            qs = qs.at[t].set(d.qpos)
        return (d, carry, ovf, qs), None

    if frame_skip == 1:  # the chapter's schedule acts every physics step: no inner loop
        (d, carry, ovf, qs), _ = physics_step((d, carry, ovf, qs), 0)
    else:
        (d, carry, ovf, qs), _ = jax.lax.scan(physics_step, (d, carry, ovf, qs), jnp.arange(frame_skip))
    return d, carry, ovf, qs


class MjxRunner:
    """Holds one put-on-device model and its jitted rollouts, one per (batch size, trace)."""

    def __init__(self, scenario: Scenario, cfg: MjxConfig = MjxConfig(), *, devices=None):
        import jax

        if cfg.impl not in IMPLS:
            raise ValueError(f"unknown MJX impl {cfg.impl!r}")
        if cfg.impl == "warp" and not warp_available():
            raise RuntimeError("backend mjx-warp needs warp-lang: pip install 'mujoco-mjx[warp]'")
        if cfg.x64:
            jax.config.update("jax_enable_x64", True)
        enable_compilation_cache()
        self.scenario, self.cfg = scenario, cfg
        self.scene = simulated_scene(scenario, cfg.impl)
        self.model = _mj_model(self.scene, cfg)
        self.layout = QposLayout.of(self.model)
        # this process's devices: with several processes (distributed.py) each runs its own block of rows
        self.devices = list(devices) if devices else jax.local_devices()
        self.compile_seconds = 0.0
        self._fns: dict = {}
        self.buffers = (
            cfg.contacts_per_world or START_CONTACTS_PER_WORLD,
            cfg.constraints_per_world or START_ROWS_PER_WORLD,
        )
        self.growths = 0
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
        self._model = self._put_grid()
        # x64 is process-wide in JAX: once on, every later runner computes in float64 too
        self.dtype = np.float64 if jax.config.jax_enable_x64 else np.float32

    def _grow(self) -> bool:
        """Double the per-world buffers up to the scene's geometric bounds; False when already there."""
        top = (contacts_per_world(self.model), constraints_per_world(self.model))
        if self.cfg.impl != "warp" or self.buffers >= top or self.cfg.contacts_per_world:
            return False
        self.buffers = (min(2 * self.buffers[0], top[0]), min(2 * self.buffers[1], top[1]))
        self.growths += 1
        import sys

        print(f"mjx-warp: a buffer overflowed; rerunning the chunk with {self.buffers[0]} contacts and "
              f"{self.buffers[1]} rows per world", file=sys.stderr)
        return True

    def _put_grid(self):
        """The grid's models as (treedef, leaves, batched): differing leaves carry a leading combo axis.

        Each combination is the CPU model edited and re-derived (params.apply), put on
        the device; only the leaves that differ are stacked, so the rollout gathers a
        row's model by index inside one compiled program. With no parameters swept
        there is one combination and nothing is stacked.
        """
        import jax
        import jax.numpy as jnp
        from mujoco import mjx

        from mjx_pusht.model.params import apply

        models = [apply(self.model, g) for g in self.grid] if self.scenario.params else [self.model]
        kw = {}
        if self.cfg.graph_mode is not None:
            import warp as wp

            kw["graph_mode"] = wp.JaxCallableGraphMode[self.cfg.graph_mode]
        flat = [jax.tree.flatten(mjx.put_model(m, impl=self.cfg.impl, device=self.devices[0], **kw)) for m in models]
        leaves, batched = [], []
        for column in zip(*(f[0] for f in flat)):
            same = all(np.array_equal(np.asarray(column[0]), np.asarray(c)) for c in column[1:])
            leaves.append(column[0] if same else jnp.stack([jnp.asarray(c) for c in column]))
            batched.append(not same)
        return flat[0][1], leaves, batched

    def _model_leaves(self, device=None):
        """The model's array leaves, on `device` if given."""
        import jax

        leaves = self._model[1]
        return leaves if device is None else [jax.device_put(x, device) for x in leaves]

    def _row_model(self, leaves, combo):
        """The model of one row: stacked leaves indexed by the row's parameter combination."""
        import jax

        treedef, _, batched = self._model
        return jax.tree.unflatten(treedef, [x[combo] if b else x for x, b in zip(leaves, batched)])

    @property
    def device_name(self) -> str:
        d = self.devices[0]
        return f"{d.platform}:{getattr(d, 'device_kind', d.platform)}" + (f" x{len(self.devices)}" if len(self.devices) > 1 else "")

    def _initial_data(self, device, worlds: int):
        from mujoco import mjx

        if self.cfg.impl == "warp":
            return mjx.make_data(self.model, impl="warp", device=device,
                                 naconmax=worlds * self.buffers[0], njmax=self.buffers[1])
        return mjx.make_data(self.model, impl="jax", device=device)

    def _build(self, batch: int, trace: bool):
        """Compile the rollout for one batch shape; returns launch(qpos0, key, combo) -> host arrays.

        The rollout is episode.py's: a scan over control steps (the controller inside the
        compiled program, no host round trip), each a scan over `frame_skip` physics steps.
        """
        import jax
        import jax.numpy as jnp

        model, layout = self.model, self.layout
        controller, episode = self.scenario.driver()
        warp = self.cfg.impl == "warp"
        fs, settle_step = episode.frame_skip, self.scenario.schedule.settle_steps - 1

        def one_seed(leaves, d0, qpos0, key, combo):
            mx = self._row_model(leaves, combo)

            def control_step(outer, k):
                d, carry, ovf, qs = outer
                u, carry = decide(carry, d.qpos, k, key, controller, layout, jnp)
                d, carry, ovf, traced = advance(mx, d, carry, u, k, fs, settle_step, layout, warp, ovf, qs if trace else None)
                qs = traced if trace else qs
                carry = after_control_step(carry, k, layout, d.qpos, episode, jnp)
                return (d, carry, ovf, qs), None

            d = d0.replace(qpos=qpos0)
            carry = begin(layout, qpos0, key, controller, episode, jnp)
            qs0 = jnp.zeros((episode.physics_steps if trace else 0, model.nq), qpos0.dtype)
            (d, carry, ovf, qs), _ = jax.lax.scan(
                control_step, (d, carry, jnp.zeros((), jnp.int32), qs0), jnp.arange(episode.max_steps))
            return carry, ovf, qs

        batched = jax.vmap(one_seed, in_axes=(None, None, 0, 0, 0))
        n_dev = len(self.devices)
        if n_dev > 1 and batch % n_dev:
            raise ValueError(f"batch {batch} does not divide over {n_dev} devices")
        per_dev = batch // n_dev

        def inputs(n):
            return jnp.zeros((n, model.nq), self.dtype), jnp.zeros((n, 2), jnp.uint32), jnp.zeros((n,), jnp.int32)

        t0 = time.perf_counter()
        if warp and n_dev > 1:
            # One single-device program per GPU, each run from its own thread on its own
            # slice of the batch. XLA cannot partition MJX-Warp's FFI call, and compiling it
            # under shard_map crashed XLA on a 2 x H200 host (segfault in backend compile),
            # while the single-device program is the one every other path runs.
            progs = []
            for dev in self.devices:
                leaves, d0 = self._model_leaves(dev), self._initial_data(dev, per_dev)
                args = jax.device_put(inputs(per_dev), dev)
                progs.append((jax.jit(batched).lower(leaves, d0, *args).compile(), leaves, d0, dev))

            def launch(qpos0, key, combo):
                def one_device(i):
                    prog, leaves, d0, dev = progs[i]
                    part = jax.tree.map(lambda x: x[i * per_dev:(i + 1) * per_dev], (qpos0, key, combo))
                    return jax.device_get(prog(leaves, d0, *jax.device_put(part, dev)))

                # A thread per GPU: the rollout's while loop reads its predicate on the host
                # every step, so one Python thread dispatching both GPUs ran them one after
                # the other (measured on 2 x H200: the pair at the one-GPU rate).
                with ThreadPoolExecutor(n_dev) as pool:
                    outs = list(pool.map(one_device, range(n_dev)))
                return jax.tree.map(lambda *xs: np.concatenate(xs), *outs)
        else:
            leaves, d0 = self._model_leaves(), self._initial_data(self.devices[0], per_dev)
            fn = functools.partial(batched, leaves, d0)  # model and data as constants of the program
            sharding = self._sharding(batch)
            if sharding is not None:
                # shard_map, so each device steps only its own worlds; check_vma is off because
                # MJX-Warp's FFI drops the varying-axis type of its outputs, which lax.scan then
                # rejects as a carry mismatch (mujoco#3426).
                spec = sharding.spec
                fn = jax.shard_map(fn, mesh=sharding.mesh, in_specs=(spec,) * 3, out_specs=spec, check_vma=False)
            args = inputs(batch) if sharding is None else jax.device_put(inputs(batch), sharding)
            prog = jax.jit(fn).lower(*args).compile()

            def launch(qpos0, key, combo):
                args = (qpos0, key, combo) if sharding is None else jax.device_put((qpos0, key, combo), sharding)
                return jax.device_get(prog(*args))
        self.compile_seconds += time.perf_counter() - t0
        return launch

    def _sharding(self, batch: int):
        if len(self.devices) == 1:
            return None
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        mesh = Mesh(np.array(self.devices), ("seeds",))
        return NamedSharding(mesh, PartitionSpec("seeds"))

    def run(self, seeds: np.ndarray, *, trace: bool = False, batch: int | None = None, combos=None,
            poses: np.ndarray | None = None) -> Rollouts:
        """Roll out `seeds` (padded up to `batch` so one compiled shape serves every chunk)."""
        return self.collect(self.submit(seeds, trace=trace, batch=batch, combos=combos, poses=poses))

    def submit(self, seeds: np.ndarray, *, trace: bool = False, batch: int | None = None, combos=None,
               poses: np.ndarray | None = None) -> "Pending":
        """Start a rollout on the device thread and return at once; `collect` waits for it and scores it.
        A sweep submits chunk k + 1 before it collects chunk k, so the host's work hides behind the device's."""
        import jax.numpy as jnp

        seeds = np.asarray(seeds, dtype=np.int64)
        n = len(seeds)
        batch = batch or n
        if n > batch:
            raise ValueError(f"{n} seeds do not fit a batch of {batch}")
        key = (batch, trace, self.buffers)
        if key not in self._fns:
            self._fns[key] = self._build(batch, trace)
        launch = self._fns[key]
        poses = start_poses(seeds, reset=self.scenario.reset) if poses is None else poses
        qpos0 = self.layout.initial_qpos(self.model, np.concatenate([poses, np.repeat(poses[-1:], batch - n, 0)]))
        rng_key = seed_key(np.concatenate([seeds, np.repeat(seeds[-1:], batch - n)]))
        combos = np.zeros(n, np.int64) if combos is None else np.asarray(combos, np.int64)
        combo = np.concatenate([combos, np.repeat(combos[-1:], batch - n)]).astype(np.int32)
        qpos0 = np.asarray(qpos0, self.dtype)
        future = _device_thread().submit(lambda: launch(jnp.asarray(qpos0), jnp.asarray(rng_key), jnp.asarray(combo)))
        return Pending(seeds, poses, combos, qpos0, batch, trace, future)

    def collect(self, p: "Pending") -> Rollouts:
        """The submitted rollout's rows, checked: dropped contacts grow the buffers and rerun, or fail loudly."""
        import jax

        seeds, poses, combos, n = p.seeds, p.poses, p.combos, len(p.seeds)
        carry, ovf, qs = p.future.result()
        ovf = np.asarray(ovf)[:n]
        dropped = (ovf & _DROP_BITS) != 0
        if dropped.any() and self._grow():
            return self.run(seeds, trace=p.trace, batch=p.batch, combos=combos, poses=poses)
        if dropped.any():
            raise BufferOverflow(
                f"MJX-Warp buffers overflowed in {int(dropped.sum())} of {n} seeds (bits {int(np.bitwise_or.reduce(ovf)):#x}): "
                "contacts or constraint rows were dropped, so these results are not physics; "
                f"the buffers were fixed at {self.buffers} (contacts, rows) per world: raise them"
            )
        trace, qpos0 = p.trace, p.qpos0
        f64 = lambda a: np.asarray(a, np.float64)[:n]  # noqa: E731
        carry = jax.tree.map(lambda a: np.asarray(a)[:n], carry)
        q0 = np.asarray(qpos0, np.float64)[:n]
        out = from_carry(seeds, poses, self.layout.pusher_xy(q0), carry)
        if self.scenario.params:
            out.params = {name: np.array([self.grid[c][name] for c in combos]) for name, _ in self.scenario.params}
        if trace:
            out.trace = Trace(np.concatenate([q0[:, None], f64(qs)], axis=1), float(self.model.opt.timestep),
                              self.scenario.driver()[1].frame_skip)
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


@functools.lru_cache(maxsize=8)
def runner(scenario: Scenario, cfg: MjxConfig = MjxConfig()) -> MjxRunner:
    return MjxRunner(scenario, cfg)
