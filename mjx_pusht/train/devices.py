"""The devices a training run spreads over (`train --devices N`), and how DAgger's work is laid over them.

Rollouts: a program per device, each on its own contiguous block of the seeds, from a thread of its own (as the
sweep's `backends/launch.per_device`: XLA cannot partition MJX-Warp's FFI call, and a program per GPU is the one
path every backend runs), the blocks' rows then one global array, in seed order, sharded over the devices.
The learner: one program over the devices' mesh (`Learner`, shard_map), each device the gradient of its share
of every minibatch, the shares averaged: one set of weights, the mean gradient of the whole minibatch.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from mjx_pusht.train.resume import TrainError

AXIS = "devices"  # the mesh's one axis: the batch's rows (seeds in a rollout, samples in a minibatch)


def training_devices(count: int | None, backend: str, pixels: bool = False) -> list:
    """This process's first `count` devices (None: every one) that `backend`'s training runs on, or a one-line
    TrainError: more than there are, a count on the cpu backend (MuJoCo C steps on the host's cores, its learner
    on JAX's default device)."""
    import jax

    if backend == "cpu":
        if count is not None:
            raise TrainError("--devices spreads training over the devices of the mjx-jax or mjx-warp backends; "
                             "the cpu backend steps MuJoCo C on the host's cores")
        return jax.local_devices()[:1]
    # Warp's render context (its buffers) lives on one device, and the learner renders inside the one program
    # shard_map lays over all of them: a context per device is not built yet, so a pixel student takes one
    if pixels and count is not None and count > 1:
        raise TrainError(f"--devices {count}: DAgger from pixels trains on one device so far (Warp's render "
                         "context is one device's); pass --devices 1")
    local = jax.local_devices()
    if count is not None and count > len(local):
        raise TrainError(f"--devices {count}: this process has {len(local)} "
                         f"({local[0].platform}: {getattr(local[0], 'device_kind', local[0].platform)})")
    return local[:1] if pixels else local if count is None else local[:count]


def check_divides(devices: list, **sizes: int) -> None:
    """A one-line TrainError unless every size (a flag's name: its value) splits evenly over the devices."""
    for name, n in sizes.items():
        if n % len(devices):
            raise TrainError(f"--{name.replace('_', '-')} ({n}) must be a multiple of the {len(devices)} devices it "
                             "is split over (--devices)")


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

    def blocks(self, n: int) -> list[slice]:
        """Each device's rows of `n` (a multiple of the device count), in order."""
        m = n // len(self)
        return [slice(i * m, (i + 1) * m) for i in range(len(self))]

    def sharding(self, axis: int | None):
        """Rows along `axis` split over the devices (None: every device holds the whole array)."""
        from jax.sharding import NamedSharding, PartitionSpec

        return NamedSharding(self.mesh, PartitionSpec(*(None,) * axis, AXIS) if axis is not None else PartitionSpec())

    def replicate(self, tree):
        import jax

        return jax.device_put(tree, self.sharding(None))

    def each(self, fn, args: list) -> list:
        """`fn(device, *args[i])` on device i, from a thread each (a rollout's scan dispatches from the host: one
        thread driving every device would run them one after another, as the sweep measured), results in order."""
        if len(self) == 1:
            return [fn(self.devices[0], *args[0])]
        with ThreadPoolExecutor(len(self)) as pool:
            return list(pool.map(fn, self.devices, *zip(*args)))

    def join(self, parts: list, axis: int):
        """The devices' arrays (each on its own device, in order) as one array, their rows along `axis`."""
        import jax

        if len(self) == 1:
            return parts[0]
        shape = list(parts[0].shape)
        shape[axis] *= len(parts)
        return jax.make_array_from_single_device_arrays(tuple(shape), self.sharding(axis), parts)
