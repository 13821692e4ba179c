"""MuJoCo Warp's kernels: find the ones this scene launches and compile them on every core at once.

Warp compiles a module the first time one of its kernels launches, one after the other, so
MJX-Warp's first call on a fresh machine is mostly compilation (93-134 s on an H100 host,
docs/notebook.md). `precompile` steps MuJoCo Warp once with every launch recorded instead of
run, which names the modules this scene needs without compiling anything, then compiles those
in parallel. What the recording misses still compiles lazily at first launch, as before, so the
worst case is the old one.
"""

from __future__ import annotations

import contextlib
import os
import time
from concurrent.futures import ThreadPoolExecutor

import mujoco

from mjx_pusht.model import mjx_private


@contextlib.contextmanager
def _launches_recorded(need: set):
    """Inside: wp.launch / wp.launch_tiled record (module, block_dim) and run nothing.

    Both branches of wp.capture_if and one pass of a wp.capture_while body are taken, so the
    kernels behind data-dependent control flow (the solver loop) are created too. CUDA occupancy
    queries (wp.get_suggested_block_size, which MuJoCo Warp uses to size grids) would load, so
    compile, the kernel's module on the spot, one at a time: they get a placeholder answer.
    """
    import warp as wp

    def record(kernel, *args, block_dim=None, **kwargs):
        need.add((kernel.module, block_dim))

    def both_branches(condition, on_true=None, on_false=None, **kwargs):
        for branch in (on_true, on_false):
            if callable(branch):
                branch(**kwargs)

    def body_once(condition, while_body, **kwargs):
        while_body(**kwargs)

    def occupancy(kernel, *args, **kwargs):
        return 256, 1  # sizes grids that are never launched; the launch that follows records the module

    # The patch is process-wide: an MJX-Warp call still running on XLA's thread (JAX dispatches
    # asynchronously, and a step whose result is never read, as one that raised, runs on) would have
    # its launches recorded instead of run. Its solver loop then never ends (wp.capture_while reads
    # nsolving, which only the skipped kernels decrement): a silent hang. Warp runs every JAX FFI
    # callback under one lock, so holding it here waits for a running call and holds back the next.
    with _ffi_callbacks_held():
        saved = wp.launch, wp.launch_tiled, wp.capture_if, wp.capture_while, wp.get_suggested_block_size
        wp.launch, wp.launch_tiled, wp.capture_if, wp.capture_while = record, record, both_branches, body_once
        wp.get_suggested_block_size = occupancy
        try:
            yield
        finally:
            wp.launch, wp.launch_tiled, wp.capture_if, wp.capture_while, wp.get_suggested_block_size = saved


def _ffi_callbacks_held():
    """Warp's lock around its JAX FFI callbacks (private: no lock, nothing held, if a Warp version moves it)."""
    try:
        from warp._src.jax.ffi import _FFI_CALLBACK_LOCK
    except ImportError:
        return contextlib.nullcontext()
    return _FFI_CALLBACK_LOCK


def scene_modules(model: mujoco.MjModel, device=None) -> set:
    """(module, block_dim) for every Warp module one MuJoCo Warp step launches on `model`; nothing is compiled."""
    import warp as wp
    mjw = mjx_private.mujoco_warp()
    need: set = {(wp.get_module(mjx_private.FFI_MODULE), None)}
    with wp.ScopedDevice(device):
        m = mjw.put_model(model)
        # one world, small buffers: the kernels a step creates depend on the model, not the batch;
        # njmax > 0 so the constraint solver's path is taken
        d = mjw.put_data(model, mujoco.MjData(model), nworld=1, nconmax=16, njmax=48)
        with _launches_recorded(need):
            mjw.step(m, d)
    return need


def warp_device(jax_device):
    """The Warp device a JAX device runs MJX-Warp on."""
    import warp as wp

    if jax_device.platform == "gpu":
        # the CUDA ordinal this process sees: under jax.distributed with one visible GPU a process, the
        # device's global id (what wp.device_from_jax reads) names a GPU this process does not have
        return wp.get_cuda_device(jax_device.local_hardware_id)
    return wp.device_from_jax(jax_device)


def precompile(model: mujoco.MjModel, jax_devices, workers: int | None = None) -> dict:
    """Compile the scene's MuJoCo Warp kernels for `jax_devices` on `workers` threads (default: all cores).

    Returns modules found, seconds to find them and seconds to compile them (or load them from
    Warp's kernel cache, under 1 s when warm). If the dry step fails (an internal change in
    MuJoCo Warp), nothing is compiled here and the returned dict says why: the kernels then
    compile at first launch, as without this.
    """
    import warp as wp

    workers = workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    devices = [warp_device(d) for d in jax_devices]
    try:
        need = scene_modules(model, devices[0])
    except Exception as e:
        return {"modules": 0, "error": f"{type(e).__name__}: {e}"}
    found = time.perf_counter() - t0
    # One pool over every (module, block_dim): the slowest modules, MuJoCo Warp's GJK/EPA kernels
    # (35 s of NVRTC each on an H100 host), start first and set the wall time; a pool per
    # block_dim group would add the groups' times up (52 s instead of 36 s, measured).
    jobs = sorted(need, key=lambda j: ("ccd" not in j[0].name, j[0].name, str(j[1])))
    with ThreadPoolExecutor(workers) as pool:
        for f in [pool.submit(wp.force_load, device=devices, modules=[m], block_dim=bd, max_workers=0) for m, bd in jobs]:
            f.result()
    return {"modules": len(jobs), "find_seconds": round(found, 3),
            "compile_seconds": round(time.perf_counter() - t0 - found, 3), "workers": workers}
