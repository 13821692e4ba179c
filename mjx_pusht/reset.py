"""The reset contract: seed -> start pose, the single source of start poses for every backend.

One PCG64 generator per seed draws x, then y, then yaw, in that order, so seed s
starts the same in a sweep of a million as in `mjx-pusht scene --seed s`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import mujoco
import numpy as np

TEE_X_RANGE = (-0.03, 0.03)
TEE_Y_RANGE = (0.02, 0.06)
TEE_YAW_RANGE = (-0.2, 0.2)
PUSHER_START_Y = -0.25


def start_pose(seed: int) -> tuple[float, float, float]:
    """The tee's (x, y, yaw) start for one seed, drawn exactly as the chapter draws it."""
    rng = np.random.default_rng(seed)
    x = float(rng.uniform(*TEE_X_RANGE))
    y = float(rng.uniform(*TEE_Y_RANGE))
    yaw = float(rng.uniform(*TEE_YAW_RANGE))
    return x, y, yaw


def _serial_poses(seeds) -> np.ndarray:
    return np.array([start_pose(int(s)) for s in seeds], dtype=np.float64).reshape(-1, 3)


_POOL_MIN = 50_000  # below this a process pool costs more than it saves (~20 us a seed serially)


def start_poses(seeds: Sequence[int] | np.ndarray, *, workers: int | None = None) -> np.ndarray:
    """(N, 3) float64 start poses, row i from seed i's own generator.

    Seeding a PCG64 generator per seed costs ~20 us, 20 s for a million seeds, so
    large sweeps split the seeds over processes; every row is still drawn by
    `start_pose`, so the values are the same either way.
    """
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if len(seeds) < _POOL_MIN or workers < 2:
        return _serial_poses(seeds)
    parts = np.array_split(seeds, 4 * workers)
    # spawn, not fork: the caller may already run JAX/XLA threads, which fork would copy mid-flight
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        return np.concatenate(list(pool.map(_serial_poses, parts)))


@dataclasses.dataclass(frozen=True)
class QposLayout:
    """Where the tee's pose and the pusher live in qpos, found by joint name.

    Planar variants read (x, y, yaw) from three joints; the free-tee variant reads
    position and a quaternion from one free joint.
    """

    tee: tuple[int, int, int] | None  # planar: qpos addresses of tee_x, tee_y, tee_yaw
    tee_free: int | None  # free-tee: qpos address of the free joint
    pusher: tuple[int, int]
    nq: int

    @classmethod
    def of(cls, model: mujoco.MjModel) -> "QposLayout":
        def adr(name: str) -> int:
            return int(model.joint(name).qposadr[0])

        names = {model.joint(j).name for j in range(model.njnt)}
        if "tee_free" in names:
            tee, free = None, adr("tee_free")
        else:
            tee, free = (adr("tee_x"), adr("tee_y"), adr("tee_yaw")), None
        return cls(tee, free, (adr("pusher_x"), adr("pusher_y")), int(model.nq))

    def tee_pose(self, qpos):
        """(..., 3) tee (x, y, yaw) from (..., nq) qpos; NumPy or JAX arrays alike."""
        xp = qpos.__array_namespace__()
        if self.tee is not None:
            return qpos[..., list(self.tee)]
        a = self.tee_free
        w, x, y, z = (qpos[..., a + 3 + k] for k in range(4))
        yaw = xp.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        return xp.stack([qpos[..., a], qpos[..., a + 1], yaw], axis=-1)

    def pusher_xy(self, qpos):
        return qpos[..., list(self.pusher)]

    def initial_qpos(self, model: mujoco.MjModel, poses: np.ndarray) -> np.ndarray:
        """(N, nq) start qpos: qpos0 with the tee at each pose and the pusher south of it.

        Only the tee's own joints are seeded; in split-tee the stem body keeps its
        qpos0, which is exactly why that T cannot be set down as one piece.
        """
        qpos = np.tile(model.qpos0, (len(poses), 1))
        if self.tee is not None:
            qpos[:, list(self.tee)] = poses
        else:
            a = self.tee_free
            qpos[:, a], qpos[:, a + 1] = poses[:, 0], poses[:, 1]
            qpos[:, a + 3] = np.cos(poses[:, 2] / 2)
            qpos[:, a + 4 : a + 6] = 0.0
            qpos[:, a + 6] = np.sin(poses[:, 2] / 2)
        qpos[:, self.pusher[1]] = PUSHER_START_Y
        return qpos
