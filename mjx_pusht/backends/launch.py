"""How one compiled rollout is laid over this process's devices: one device, shard_map, or a program per GPU.

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
    """One single-device program per GPU, each run from its own thread on its own slice of the batch.

    XLA cannot partition MJX-Warp's FFI call, and compiling it under shard_map crashed XLA on a
    2 x H200 host (segfault in backend compile), while the single-device program is the one
    every other path runs.
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


def one_program(batched, devices, leaves, d0, batch: int, nq: int, dtype, k: int):
    """One program: on one device, or shard_map'd over several so each steps only its own worlds."""
    import jax

    t0 = time.perf_counter()
    fn = functools.partial(batched, leaves, d0)  # model and data as constants of the program
    sharding = None
    if len(devices) > 1:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        sharding = NamedSharding(Mesh(np.array(devices), ("seeds",)), PartitionSpec("seeds"))
        # check_vma is off because MJX-Warp's FFI drops the varying-axis type of its outputs,
        # which lax.scan then rejects as a carry mismatch (mujoco#3426).
        fn = jax.shard_map(fn, mesh=sharding.mesh, in_specs=(sharding.spec,) * 4, out_specs=sharding.spec,
                           check_vma=False)
    args = _inputs(batch, nq, dtype, k)
    prog = jax.jit(fn).lower(*(args if sharding is None else jax.device_put(args, sharding))).compile()

    def launch(*rows):
        args = rows if sharding is None else jax.device_put(rows, sharding)
        return jax.device_get(prog(*args))

    return launch, time.perf_counter() - t0
