"""MuJoCo Warp's per-world buffers: sized from the measured need, grown on overflow, never silently short.

MJX-Warp keeps contacts and constraint rows in buffers shared by all worlds of a batch
(`naconmax = worlds x contacts per world`, `njmax` rows per world). Sizing them at the
scene's geometric bound wastes memory that grows with the batch (MuJoCo Warp's EPA scratch
is sized from them: 16 GB at 65,536 worlds), so they start at the typical need and every
step's overflow bits are checked: a result from a step that dropped a contact is never
returned as physics.
"""

from __future__ import annotations

import dataclasses
import os
import sys

import mujoco
import numpy as np

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.model.colliders import collision_pairs

# Warp overflow bits that mean something was dropped (contacts, constraint rows),
# as opposed to the solver merely reaching its iteration limit.
DROP_BITS = (1 << 0) | (1 << 1) | (1 << 2) | (1 << 3) | (1 << 4) | (1 << 7) | (1 << 8)
_MAX_CONTACTS_PER_PAIR = 8  # box-box, the richest pair in this scene, makes at most 8

# Where the buffers start: the CPU never sees more than 8 contacts (27 rows) in one world of
# this scene. A chunk that overflows is rerun with doubled buffers, up to the geometric bounds.
START_CONTACTS_PER_WORLD = 16
START_ROWS_PER_WORLD = 48
# The environment cannot rerun a step, and a policy drives the pusher anywhere: on one H100, 30 steps
# of a random linear policy overflowed 48 rows (NEFC) in 20 of 16,384 worlds (docs/notebook.md,
# change 10), while MuJoCo C saw at most 35 rows in 64 such episodes; 96 rows ran out of GPU memory
# at 65,536 worlds (Warp's solver scratch grows with rows squared). 64 rows, checked every step.
ENV_ROWS_PER_WORLD = 64


class BufferOverflow(MjxPushtError, RuntimeError):
    """MJX-Warp ran out of contact or constraint buffer: contacts were dropped."""


def warp_available() -> bool:
    try:
        import warp  # noqa: F401
    except ImportError:
        return False
    return True


def quiet_warp() -> None:
    """Warp prints a line per kernel module it loads (~45 for this scene) before the first useful line; off
    unless MJX_PUSHT_VERBOSE is set (the CLI's --verbose). The summary keeps Warp's version and device."""
    try:
        import warp
    except ImportError:
        return
    verbose = bool(os.environ.get("MJX_PUSHT_VERBOSE"))
    warp.config.quiet = not verbose  # the "Warp x.y initialized" banner
    # the per-module "Module ... load on device ... took ... ms" lines print at log level INFO and below
    warp.config.log_level = warp.LOG_INFO if verbose else warp.LOG_WARNING


_EXIT_WAIT = []  # the atexit hook, registered once per process


def finish_before_exit(device) -> None:
    """On a CPU, wait at exit for the MJX-Warp work still in flight, before the interpreter finalizes.

    Warp's FFI kernels are ctypes callbacks: XLA's CPU worker threads call back into Python, and need the GIL.
    A step dispatched and never read (the README's tour: `state = env.step(...)` as the script's last line) is
    still running when Python exits; once finalization has begun that worker waits for a GIL it never gets,
    and JAX's CPU client destructor waits for the worker: the process never exits (6 of 6 runs). `atexit`
    hooks run before finalization, so blocking there on every live array lets the callbacks finish. GPUs need
    no wait (Warp launches CUDA kernels there, with no Python in the worker)."""
    if _EXIT_WAIT or device.platform != "cpu":
        return
    import atexit

    def wait() -> None:
        import jax

        jax.block_until_ready(device.client.live_arrays())  # the client's: every device of the process

    _EXIT_WAIT.append(wait)
    atexit.register(wait)


def banner() -> str | None:
    """Warp's one-line identity for summary.json: version and the device it runs on."""
    try:
        import warp
    except ImportError:
        return None
    return f"Warp {warp.config.version} on {warp.get_preferred_device()}"


def contacts_per_world(model: mujoco.MjModel) -> int:
    """An upper bound on simultaneous contacts in one world, from the scene's geometry."""
    return len(collision_pairs(model)) * _MAX_CONTACTS_PER_PAIR


def constraints_per_world(model: mujoco.MjModel, contacts: int | None = None) -> int:
    """Rows: pyramidal friction gives 2*(condim-1) rows a contact, plus one per frictionloss DOF."""
    condim = int(model.geom_condim.max())
    contacts = contacts_per_world(model) if contacts is None else contacts
    return contacts * max(1, 2 * (condim - 1)) + int(model.nv)


@dataclasses.dataclass
class Buffers:
    """Contacts and rows per world; `fixed` buffers (set by hand) never grow, so an overflow raises."""

    model: mujoco.MjModel
    contacts: int | None = None  # None: START_CONTACTS_PER_WORLD
    rows: int | None = None  # None: START_ROWS_PER_WORLD
    fixed: bool = False
    growths: int = 0

    def __post_init__(self) -> None:
        self.contacts = self.contacts or START_CONTACTS_PER_WORLD
        self.rows = self.rows or START_ROWS_PER_WORLD

    @property
    def sizes(self) -> tuple[int, int]:
        return self.contacts, self.rows

    def make_data(self, worlds: int, device=None):
        from mujoco import mjx

        return mjx.make_data(self.model, impl="warp", device=device, naconmax=worlds * self.contacts, njmax=self.rows)

    def grow(self) -> bool:
        """Double both up to the scene's geometric bounds; False when fixed or already there."""
        top = (contacts_per_world(self.model), constraints_per_world(self.model))
        if self.fixed or self.sizes >= top:
            return False
        self.contacts, self.rows = min(2 * self.contacts, top[0]), min(2 * self.rows, top[1])
        self.growths += 1
        print(f"mjx-warp: a buffer overflowed; rerunning with {self.contacts} contacts and {self.rows} rows per world",
              file=sys.stderr)
        return True

    def check(self, ovf) -> None:
        """Raise when any world's overflow bits say something was dropped (after growing failed or was not tried)."""
        ovf = np.asarray(ovf)
        dropped = (ovf & DROP_BITS) != 0
        if dropped.any():
            raise BufferOverflow(
                f"MJX-Warp buffers overflowed in {int(dropped.sum())} of {ovf.size} worlds (bits "
                f"{int(np.bitwise_or.reduce(ovf.reshape(-1))):#x}): contacts or constraint rows were dropped, so these "
                f"results are not physics; the buffers were {self.sizes} (contacts, rows) per world: raise them")

    def info(self) -> dict:
        return {"contacts_per_world": self.contacts, "rows_per_world": self.rows, "growths": self.growths}


def dropped(ovf) -> np.ndarray:
    """Per world: did this step (or episode) drop a contact or a constraint row?"""
    return (np.asarray(ovf) & DROP_BITS) != 0
