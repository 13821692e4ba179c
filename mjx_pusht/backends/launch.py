"""How one compiled rollout is laid over this process's devices: one program on one device, or a program per device.

Each strategy returns `launch(qpos0, key, combo, drawn) -> host arrays` for a fixed batch shape (`drawn`: each
row's physics factors, (n, k), k = 0 when nothing is randomised), and the time it spent compiling.
"""

from __future__ import annotations

import functools
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np


def _inputs(n: int, nq: int, dtype, k: int):
    import jax.numpy as jnp

    return jnp.zeros((n, nq), dtype), jnp.zeros((n, 2), jnp.uint32), jnp.zeros((n,), jnp.int32), jnp.zeros((n, k), dtype)


def per_device(batched, devices, make_leaves, make_data, per_dev: int, nq: int, dtype, k: int):
    """One single-device program per device, each run from its own thread on its own slice of the batch.

    XLA cannot partition MJX-Warp's FFI call, and compiling it under shard_map crashed XLA on a
    2 x H200 host (segfault in backend compile); MJX-JAX's rollout shard_map'd over 4 H200s crashed XLA's
    compile too (jax 0.11.2, notebook lead12), while the single-device program is the one every other path runs.
    Rows do not depend on the rows beside them, so the table is the one-device table.
    """
    import jax

    t0 = time.perf_counter()
    progs = []
    for dev in devices:
        leaves, d0 = make_leaves(dev), make_data(dev, per_dev)
        args = jax.device_put(_inputs(per_dev, nq, dtype, k), dev)
        progs.append((jax.jit(batched).lower(leaves, d0, *args).compile(), leaves, d0, dev))

    def launch(*rows):
        def one_device(i):
            prog, leaves, d0, dev = progs[i]
            part = jax.tree.map(lambda x: x[i * per_dev:(i + 1) * per_dev], rows)
            return jax.device_get(prog(leaves, d0, *jax.device_put(part, dev)))

        # A thread per GPU: the rollout's while loop reads its predicate on the host every
        # step, so one Python thread dispatching both GPUs ran them one after the other
        # (measured on 2 x H200: the pair at the one-GPU rate).
        with ThreadPoolExecutor(len(progs)) as pool:
            outs = list(pool.map(one_device, range(len(progs))))
        return jax.tree.map(lambda *xs: np.concatenate(xs), *outs)

    return launch, time.perf_counter() - t0


def one_program(batched, device, leaves, d0, batch: int, nq: int, dtype, k: int):
    """One program on one device."""
    import jax

    t0 = time.perf_counter()
    fn = functools.partial(batched, leaves, d0)  # model and data as constants of the program
    prog = jax.jit(fn).lower(*jax.device_put(_inputs(batch, nq, dtype, k), device)).compile()

    def launch(*rows):
        return jax.device_get(prog(*jax.device_put(rows, device)))

    return launch, time.perf_counter() - t0
