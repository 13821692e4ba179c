"""One sweep over several processes (one a host, or one a GPU), joined through `jax.distributed`.

Each process takes a contiguous block of the sweep's rows, runs it on its own devices and writes
its chunk files, named by their rows in the whole sweep, into the shared output folder. Process 0
then waits at a barrier for every process and writes the table, the summary and the audit from
all the chunk files: the same table, to the bit, as one process writes (the rows do not depend on
which process ran them). The output folder must be one folder for all of them: the same machine,
or a shared filesystem.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht.errors import MjxPushtError

BARRIER_TIMEOUT_MS = 24 * 3600 * 1000  # a sweep may take long; a process that died is caught by JAX's heartbeat


class DistributedError(MjxPushtError, RuntimeError):
    """A multi-process run that cannot start or finish (bad ids, no coordinator): one line."""


@dataclasses.dataclass(frozen=True)
class Processes:
    """Which process this is of how many, and where process 0 listens (HOST:PORT)."""

    process_id: int = 0
    num_processes: int = 1
    coordinator: str | None = None

    def __post_init__(self) -> None:
        if self.num_processes < 1:
            raise DistributedError(f"--num-processes must be at least 1, got {self.num_processes}")
        if not 0 <= self.process_id < self.num_processes:
            raise DistributedError(f"--process-id must be from 0 to {self.num_processes - 1}, got {self.process_id}")
        if self.num_processes > 1 and not self.coordinator:
            raise DistributedError("several processes need --coordinator HOST:PORT (process 0's address)")
        if self.coordinator and (":" not in self.coordinator or not self.coordinator.rsplit(":", 1)[1].isdigit()):
            raise DistributedError(f"--coordinator must be HOST:PORT, got {self.coordinator!r}")

    @property
    def many(self) -> bool:
        return self.num_processes > 1

    @property
    def leader(self) -> bool:
        return self.process_id == 0

    def initialize(self) -> None:
        """Join the other processes (before JAX touches a device). Each then sees only its own devices."""
        if not self.many:
            return
        import jax

        try:
            jax.distributed.initialize(coordinator_address=self.coordinator, num_processes=self.num_processes,
                                       process_id=self.process_id, initialization_timeout=300)
        except Exception as e:  # noqa: BLE001 - the coordinator's errors are long; one line says enough
            raise DistributedError(f"could not join {self.num_processes} processes at {self.coordinator}: "
                                   f"{str(e).splitlines()[0]}") from None

    def block(self, n_rows: int) -> tuple[int, int]:
        """This process's rows [lo, hi) of n_rows: contiguous blocks, as even as they can be."""
        edges = np.linspace(0, n_rows, self.num_processes + 1).round().astype(int)
        return int(edges[self.process_id]), int(edges[self.process_id + 1])

    def barrier(self, name: str) -> None:
        """Wait here until every process has arrived."""
        if not self.many:
            return
        from jax._src import distributed

        distributed.global_state.client.wait_at_barrier(f"mjx_pusht:{name}", BARRIER_TIMEOUT_MS)
