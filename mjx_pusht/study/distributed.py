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
import errno
import json
import os
import socket
import sys
import threading

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
    peer_timeout: float = 300.0  # seconds to wait for every process to join, and to agree

    def __post_init__(self) -> None:  # the boundary's declared rules, before any network use
        from mjx_pusht import boundary

        given = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        names = {"process_id": "--process-id", "num_processes": "--num-processes", "coordinator": "--coordinator",
                 "peer_timeout": "--peer-timeout"}
        for name, value in given.items():
            boundary.PROCESSES[name](names[name], value, DistributedError)
        boundary.refuse_combinations(boundary.COMBINATIONS["processes"], given, DistributedError)

    @property
    def many(self) -> bool:
        return self.num_processes > 1

    @property
    def leader(self) -> bool:
        return self.process_id == 0

    def initialize(self) -> None:
        """Join the other processes (before JAX touches a device). Each then sees only its own devices.

        Two of JAX's failures here kill the process from C++ instead of raising: a coordinator port
        another program holds (a segfault) and a process that never arrives (an abort after the
        timeout). The first is checked here before JAX binds; the second is cut short, in one line,
        by a watchdog that fires before JAX's own deadline."""
        if not self.many:
            return
        import jax

        if self.leader:
            self._check_port_free()
        # collectives across processes on CPU devices (a training run's gradients, tested with 2 CPU processes) go
        # through gloo; without it JAX's CPU client has none. GPUs' collectives are NCCL's whatever this says.
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        # JAX's preemption service (on by default with jax.distributed) catches SIGTERM, logs "SIGTERM caught" and
        # carries on, for programs that poll `reached_preemption_sync_point` to checkpoint; nothing here polls, so a
        # `kill`, `timeout`, `docker stop` or Slurm's scancel left a sweep or training running (a 2-process sweep
        # ran on 30 s after it; a training on 2 H200s finished its run, notebook lead20): SIGTERM stops it again
        jax.config.update("jax_enable_preemption_service", False)
        same_program_text()
        joined = threading.Event()
        threading.Thread(target=self._watchdog, args=(joined,), daemon=True, name="join-watchdog").start()
        try:
            jax.distributed.initialize(coordinator_address=self.coordinator, num_processes=self.num_processes,
                                       process_id=self.process_id,
                                       initialization_timeout=int(self.peer_timeout) + 60)  # ours fires first
        except Exception as e:  # noqa: BLE001 - the coordinator's errors are long; one line says enough
            raise DistributedError(f"could not join {self.num_processes} processes at {self.coordinator}: "
                                   f"{str(e).splitlines()[0]}") from None
        finally:
            joined.set()

    def _check_port_free(self) -> None:
        port = int(self.coordinator.rsplit(":", 1)[1])
        for family, addr in ((socket.AF_INET6, "::"), (socket.AF_INET, "")):
            try:
                with socket.socket(family, socket.SOCK_STREAM) as s:
                    s.bind((addr, port))
                return
            except OSError as e:
                if e.errno == errno.EADDRINUSE:
                    raise DistributedError(f"--coordinator {self.coordinator}: port {port} is in use by another "
                                           "program; choose another port") from None
                # no IPv6 here: try IPv4

    def _watchdog(self, joined: threading.Event) -> None:
        if not joined.wait(self.peer_timeout):
            print(f"mjx-pusht: error: not all {self.num_processes} processes joined at {self.coordinator} within "
                  f"{self.peer_timeout:g} s (--peer-timeout): start the missing ones with the same --coordinator",
                  file=sys.stderr, flush=True)
            os._exit(1)

    def agree(self, settings: dict) -> None:
        """Raise in every process, before any row is written, if any two were given other settings
        (seeds, scene, steps, parameters, --out): their rows would be mixed into one table."""
        if not self.many:
            return
        # the process count too: a process given another --num-processes joined, ran its own block of rows and mixed
        # them into the table's chunks (the fifteenth pass)
        mine = json.dumps({**settings, "num_processes": self.num_processes}, sort_keys=True, default=str)
        settings = json.loads(mine)  # compared as every process sees it: through JSON
        # compared as each arrives, in process order: a process told of one process too many must not wait for it
        # before it sees that process 0 was told otherwise
        for i, given in enumerate(each_process("settings", mine, int(self.peer_timeout * 1000))):
            theirs = json.loads(given)
            if theirs != settings:
                diff = "; ".join(f"{k} {settings.get(k)} here, {theirs.get(k)} there"
                                 for k in sorted({*theirs, *settings}) if theirs.get(k) != settings.get(k))
                raise DistributedError(f"process {i} was given other settings than process {self.process_id} "
                                       f"({diff}): give every process the same options; nothing was written")

    def settled(self, name: str, step=None):
        """`step()` in this process (process 0's claim of the run's folder; None where a process has none), then every
        process hears whether each one's went through: a refusal in one ends every process in one line. Refused in
        process 0 alone, its --out claim left the others waiting for it at their next barrier or collective for ever
        (a sweep's process 1 at "parts-ready", 24 hours; the fast loop, notebook lead29). Returns `step`'s result."""
        try:
            result = None if step is None else step()
        except Exception as e:  # noqa: BLE001 - told to the others, then raised here as it was
            if self.many:
                every_process(f"settled:{name}", f"{type(e).__name__}: {(str(e).splitlines() or [''])[0]}")
            raise
        if self.many:
            for i, theirs in enumerate(every_process(f"settled:{name}", "")):
                if theirs:
                    raise DistributedError(f"process {i} stopped before any work ({theirs}): nothing was run here")
        return result

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


def same_program_text() -> None:
    """Make a program the processes run together lower to the same HLO text in each of them, whatever Python line
    called it and wherever the package is installed.

    By default JAX writes every op's whole Python call stack, with absolute paths, into the HLO, and XLA's fingerprint
    of a module covers it; process 0 calls training from another line than the others (`_follow`). XLA's GPU compiler
    shares its autotuning between the processes that compile one program, keyed by that fingerprint (openxla/xla
    #13108; a hang of this kind: marin-community/marin#9042; inferred here, not observed). Brax's PPO over 2
    processes, a GPU each, was still compiling its first epoch at 170 s, over 4 it never left that epoch (H200s,
    notebook lead23); with the texts the same (this, and the judge every PPO process runs, train/ppo_judge.py) 2 processes
    trained to the end in 127 s. One frame an op (its own line, the same in every process) and file names without
    their folders make the texts agree."""
    import jax

    jax.config.update("jax_include_full_tracebacks_in_locations", False)
    jax.config.update("jax_hlo_source_file_canonicalization_regex", r".*/")


def every_process(name: str, value: str, timeout_ms: int = BARRIER_TIMEOUT_MS) -> list[str]:
    """`value` from every process joined through jax.distributed, in process order (each process gives its own under
    `name`, once), through the coordinator's key-value store; waits for each at most `timeout_ms`."""
    return list(each_process(name, value, timeout_ms))


def each_process(name: str, value: str, timeout_ms: int = BARRIER_TIMEOUT_MS):
    """As `every_process`, `value` given at once, the others' read one at a time as the iterator is advanced."""
    import jax
    from jax._src import distributed

    client = distributed.global_state.client
    client.key_value_set(f"mjx_pusht:{name}:{jax.process_index()}", value)
    return (client.blocking_key_value_get(f"mjx_pusht:{name}:{i}", timeout_ms) for i in range(jax.process_count()))


def leave_peers(code: int) -> None:
    """End a process joined to others through jax.distributed, once its command has ended: it waits for the others
    at JAX's shutdown barrier and then exits at once, with `code`. Left to Python's exit, JAX tore its client down
    before that barrier, and a process still leaving when process 0's coordination service went away was aborted by
    the service client's own thread (SIGABRT in both processes of a two-process sweep in CI, after each had written
    its rows; marin-community/marin#8392 reports the same teardown race). Alone, a process returns from here."""
    if "jax" not in sys.modules:
        return
    from jax._src import distributed

    if distributed.global_state.client is None:
        return
    import jax

    from mjx_pusht.io.outputs import finish_background_writes

    finish_background_writes()
    jax.distributed.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
