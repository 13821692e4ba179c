"""MJX-Warp buffers and kernels: an overflow is an error or a rerun with grown buffers, never a result; the dry step finds every kernel."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_matches_cpu

from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.scenario import Scenario


@pytest.mark.slow
@pytest.mark.warp
def test_warp_buffers_too_small_to_hold_the_contacts_are_an_error_not_a_result():
    from mjx_pusht.backends.mjx import MjxBackend
    from mjx_pusht.backends.warp import BufferOverflow, warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    backend = MjxBackend(Scenario(), "warp", contacts_per_world=1, constraints_per_world=4)
    with pytest.raises(BufferOverflow, match="dropped"):
        backend.run(np.arange(8))


@pytest.mark.slow
@pytest.mark.warp
def test_warp_buffers_that_overflow_grow_and_the_chunk_is_rerun(monkeypatch, cpu_runs):
    import mjx_pusht.backends.warp as rm
    from mjx_pusht.backends.mjx import MjxBackend

    if not rm.warp_available():
        pytest.skip("warp-lang is not installed")
    monkeypatch.setattr(rm, "START_CONTACTS_PER_WORLD", 1)
    monkeypatch.setattr(rm, "START_ROWS_PER_WORLD", 4)
    backend = MjxBackend(Scenario(), "warp")
    rows = backend.run(np.arange(8))
    assert backend.runner.buffers.sizes > (1, 4)
    assert_matches_cpu(rows, cpu_runs[("none", "cylinder")])


@pytest.mark.slow
def test_the_dry_step_finds_every_warp_module_a_real_step_launches(mjx_warp_runs):
    """The up-front parallel compile is only complete if the recorded step saw every module the real one uses."""
    import mujoco
    import warp as wp

    from mjx_pusht.model import mjx_private
    from mjx_pusht.backends.mjx import MjxConfig, mjx_model, simulated_scene
    from mjx_pusht.backends.warp_kernels import scene_modules

    mjw = mjx_private.mujoco_warp()
    for break_it in ("none", "split-tee"):
        model = mjx_model(simulated_scene(Scenario(SceneSpec(break_it)), "warp"), MjxConfig(impl="warp"))
        found = {module for module, _ in scene_modules(model, "cpu")}
        launched = set()
        real_launch = wp.launch

        def spy(kernel, *args, **kwargs):
            launched.add(kernel.module)
            return real_launch(kernel, *args, **kwargs)

        m, d = mjw.put_model(model), mjw.put_data(model, mujoco.MjData(model), nworld=2, nconmax=16, njmax=48)
        wp.launch = spy
        try:
            for _ in range(3):
                mjw.step(m, d)
        finally:
            wp.launch = real_launch
        assert launched and launched <= found, sorted(x.name for x in launched - found)


@pytest.mark.slow
@pytest.mark.warp
def test_the_dry_step_never_swaps_warps_launches_under_a_running_mjx_warp_call():
    """The dry step swaps wp.launch and the capture loops for recorders, process-wide. An MJX-Warp call still
    running on XLA's thread (JAX returns before a step ends, and a step that raised is never waited for) would then
    have its solver's launches recorded, not run, and wp.capture_while would wait forever on a counter no kernel
    lowers: the hang once seen in CI. So the dry step waits for the lock Warp holds around every JAX FFI call."""
    import sys
    import threading
    import time

    import warp as wp
    from warp._src.jax.ffi import _FFI_CALLBACK_LOCK  # moved in a Warp upgrade: this fails, not the guard silently

    from mjx_pusht.backends.mjx import MjxConfig, mjx_model, simulated_scene
    from mjx_pusht.backends.warp_kernels import scene_modules

    def stack(thread):
        names, frame = set(), sys._current_frames().get(thread.ident)
        while frame is not None:
            names, frame = names | {frame.f_code.co_name}, frame.f_back
        return names

    model = mjx_model(simulated_scene(Scenario(SceneSpec("none")), "warp"), MjxConfig(impl="warp"))
    original = wp.launch, wp.capture_while
    swapped, waiting, found = [], 0, []
    with _FFI_CALLBACK_LOCK:  # an MJX-Warp call running
        dry = threading.Thread(target=lambda: found.append(scene_modules(model, "cpu")))
        dry.start()
        deadline = time.monotonic() + 60
        while dry.is_alive() and time.monotonic() < deadline and waiting < 200:
            swapped.append((wp.launch, wp.capture_while) != original)
            waiting += "_launches_recorded" in stack(dry)  # where it waits for the lock
            time.sleep(0.001)
        assert not any(swapped) and dry.is_alive() and waiting == 200  # it waited, nothing swapped
    dry.join(60)
    assert not dry.is_alive() and found and found[0]  # and it runs once the call ends
    assert (wp.launch, wp.capture_while) == original
