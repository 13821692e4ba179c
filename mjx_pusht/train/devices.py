"""The devices a training run spreads over (`train --devices N`), and how DAgger's work is laid over them.

Rollouts: a program per device, each on its own contiguous block of the seeds, from a thread of its own (as the
sweep's `backends/launch.per_device`: XLA cannot partition MJX-Warp's FFI call, and a program per GPU is the one
path every backend runs), the blocks' rows then one global array, in seed order, sharded over the devices.
The learner: one program over the devices' mesh (`Learner`, shard_map), each device the gradient of its share
of every minibatch, the shares averaged: one set of weights, the mean gradient of the whole minibatch.
"""

from __future__ import annotations

import gc
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

from mjx_pusht.train.resume import TrainError

AXIS = "devices"  # the mesh's one axis: the batch's rows (seeds in a rollout, samples in a minibatch)


def training_devices(count: int | None, backend: str) -> list:
    """The devices `backend`'s training runs on: this process's first `count` (None: every one), and as many of every
    other process's joined through jax.distributed; or a one-line TrainError: more than there are, a count or
    several processes on the cpu backend (MuJoCo C steps on the host's cores, its learner on JAX's default device).
    A pixel student's images, in its rollouts and its fit, are the raster renderer's (plain JAX ops, any device:
    train/run.py `dagger_env`), so it spreads as a state student does."""
    import jax

    if backend == "cpu":
        if count is not None or jax.process_count() > 1:
            raise TrainError("--devices and --num-processes spread training over the devices of the mjx-jax or "
                             "mjx-warp backends; the cpu backend steps MuJoCo C on the host's cores")
        return jax.local_devices()[:1]
    local = jax.local_devices()
    if count is not None and count > len(local):
        raise TrainError(f"--devices {count}: this process has {len(local)} "
                         f"({local[0].platform}: {getattr(local[0], 'device_kind', local[0].platform)})")
    n = len(local) if count is None else count
    # every process's first n (jax.distributed: the global devices, process by process): one mesh over them all
    return [d for p in range(jax.process_count()) for d in [d for d in jax.devices() if d.process_index == p][:n]]


def local_count(devices: list) -> int:
    """How many of `devices` (a run's, over every process) are this process's."""
    import jax

    return sum(d.process_index == jax.process_index() for d in devices)


def check_divides(devices: list, **sizes: int) -> None:
    """A one-line TrainError unless every size (a flag's name: its value) splits evenly over the devices."""
    for name, n in sizes.items():
        if n % len(devices):
            raise TrainError(f"--{name.replace('_', '-')} ({n}) must be a multiple of the {len(devices)} devices it "
                             "is split over (--devices)")


@contextmanager
def collector_paused():
    """Python's cycle collector off for the block, back as it was after. The collector runs in whichever thread
    allocates, and a Warp array or graph it finalizes in the middle of a CUDA-graph capture (MJX-Warp captures its
    step in the rollout's first call on each device) lands in, or breaks, that capture (warp#1641, warp#1714;
    mjlab#821 pauses it during captures): a rollout on several GPUs is several threads capturing. No collection
    first: one takes 0.44 s with this package's imports alone, a cost every rollout would pay."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


class Spread:
    """A batch's rows over `devices`: contiguous blocks, a program per device, the results one global array."""

    def __init__(self, devices):
        from jax.sharding import Mesh

        self.devices = list(devices)
        self.mesh = Mesh(np.array(self.devices), (AXIS,))

    def __len__(self) -> int:
        return len(self.devices)

    def check(self, n: int, what: str) -> None:
        if n % len(self):
            raise TrainError(f"{what} ({n}) must be a multiple of the {len(self)} devices it is split over (--devices)")

    def local(self, n: int) -> list[tuple]:
        """(device, its rows) of `n` (a multiple of the device count) for each device of this process, in order:
        with several processes (jax.distributed) each runs its own devices' blocks."""
        import jax

        m = n // len(self)
        return [(d, slice(i * m, (i + 1) * m)) for i, d in enumerate(self.devices)
                if d.process_index == jax.process_index()]

    def sharding(self, axis: int | None):
        """Rows along `axis` split over the devices (None: every device holds the whole array)."""
        from jax.sharding import NamedSharding, PartitionSpec

        return NamedSharding(self.mesh, PartitionSpec(*(None,) * axis, AXIS) if axis is not None else PartitionSpec())

    def replicate(self, tree):
        import jax

        return jax.device_put(tree, self.sharding(None))

    @staticmethod
    def each(fn, args: list) -> list:
        """`fn(*args[i])` for each of this process's devices (`args[i]`: that device's), from a thread each (a
        rollout's scan dispatches from the host: one thread driving every device would run them one after another,
        as the sweep measured), results in order."""
        with collector_paused():
            if len(args) == 1:
                return [fn(*args[0])]
            with ThreadPoolExecutor(len(args)) as pool:
                return list(pool.map(lambda a: fn(*a), args))

    def join(self, parts: list, axis: int):
        """This process's devices' arrays (each on its own device, in order) as one global array over every device,
        their rows along `axis` (the other processes' devices hold theirs)."""
        import jax

        if len(self) == 1:
            return parts[0]
        shape = list(parts[0].shape)
        shape[axis] *= len(self)
        return jax.make_array_from_single_device_arrays(tuple(shape), self.sharding(axis), parts)

    @staticmethod
    def own_copy(tree):
        """`tree` with each array held whole on every device of every process (the network) as this process's
        copy: what a program on one of its devices can be handed."""
        import jax

        return jax.tree.map(lambda a: a.addressable_data(0) if isinstance(a, jax.Array) and not a.is_fully_addressable
                            else a, tree)

    @staticmethod
    def gather(rows: np.ndarray) -> np.ndarray:
        """This process's rows (its devices' blocks) and every other process's, in order: the whole batch's."""
        import jax

        if jax.process_count() == 1:
            return rows
        from jax.experimental import multihost_utils

        return np.concatenate(list(multihost_utils.process_allgather(rows)))
