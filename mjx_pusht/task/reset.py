"""The reset contract: seed -> start pose, the single source of start poses for every backend.

Two distributions, each drawn from one PCG64 generator per seed (`np.random.default_rng(seed)`),
so seed s starts the same in a batch of a million as alone, on every backend:

- `chapter`: the chapter's reset. x, then y, then yaw of the tee, in that order, from small
  ranges just north of the target; the pusher starts at (0, -0.25).
- `task`: gym-pusht's random start. The tee anywhere in the walled workspace at any yaw, clear
  of the walls (x, y, yaw drawn in that order); then up to `PUSHER_TRIES` pusher positions
  (x, y pairs) anywhere in the workspace, the first one clear of the tee taken.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import mujoco
import numpy as np

from mjx_pusht.task.rules import distance_to_tee

TEE_X_RANGE = (-0.03, 0.03)
TEE_Y_RANGE = (0.02, 0.06)
TEE_YAW_RANGE = (-0.2, 0.2)
PUSHER_START_Y = -0.25
RESETS = ("chapter", "task")

# task: the walls' inner faces are at +-0.39 m. A tee centre within TASK_TEE_HALF keeps every point
# of the T (reach 0.106 m) 1 cm clear of them; a pusher centre within TASK_PUSHER_HALF keeps the
# cylinder (radius 0.015 m) 1.5 cm clear, and CLEARANCE keeps it that far from the tee's outline.
TASK_TEE_HALF = 0.27
TASK_PUSHER_HALF = 0.36
PUSHER_RADIUS = 0.015
CLEARANCE = 0.01
PUSHER_TRIES = 16  # a draw lands on the (inflated) T with p < 0.05, so 16 tries all fail with p < 1e-20


def start_pose(seed: int) -> tuple[float, float, float]:
    """The tee's (x, y, yaw) start for one seed, drawn exactly as the chapter draws it."""
    rng = np.random.default_rng(seed)
    x = float(rng.uniform(*TEE_X_RANGE))
    y = float(rng.uniform(*TEE_Y_RANGE))
    yaw = float(rng.uniform(*TEE_YAW_RANGE))
    return x, y, yaw


def task_start(seed: int) -> tuple[float, float, float, float, float]:
    """The task reset for one seed: tee (x, y, yaw) anywhere clear of the walls, then the pusher clear of the tee."""
    rng = np.random.default_rng(seed)
    x = float(rng.uniform(-TASK_TEE_HALF, TASK_TEE_HALF))
    y = float(rng.uniform(-TASK_TEE_HALF, TASK_TEE_HALF))
    yaw = float(rng.uniform(-np.pi, np.pi))
    tries = rng.uniform(-TASK_PUSHER_HALF, TASK_PUSHER_HALF, size=(PUSHER_TRIES, 2))
    clear = distance_to_tee(tries, np.array([x, y, yaw])[None]) > PUSHER_RADIUS + CLEARANCE
    px, py = tries[int(np.argmax(clear)) if clear.any() else PUSHER_TRIES - 1]  # the first clear one (the last if none)
    return x, y, yaw, float(px), float(py)


def start_state(seed: int, reset: str = "chapter") -> tuple[float, ...]:
    """Tee (x, y, yaw) and pusher (x, y) at reset for one seed."""
    if reset == "chapter":
        return (*start_pose(seed), 0.0, PUSHER_START_Y)
    if reset == "task":
        return task_start(seed)
    raise ValueError(f"unknown reset {reset!r}; choose from {', '.join(RESETS)}")


_BLOCK = 1 << 16  # seeds per block: the uint64 temporaries stay in cache


def start_poses(seeds: Sequence[int] | np.ndarray, *, reset: str = "chapter") -> np.ndarray:
    """(N, 3) float64 tee start poses for `chapter` ((N, 5) with the pusher's (x, y) for `task`),
    row i exactly what seed i's own `default_rng` draws (`start_pose`, `task_start`).

    The generators are computed for all seeds at once (pcg64.Streams, well under 1 us a seed),
    not constructed one by one (~20 us a seed).
    """
    if reset not in RESETS:
        raise ValueError(f"unknown reset {reset!r}; choose from {', '.join(RESETS)}")
    seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
    out = np.empty((len(seeds), 3 if reset == "chapter" else 5))
    for lo in range(0, len(seeds), _BLOCK):
        out[lo : lo + _BLOCK] = _draw(seeds[lo : lo + _BLOCK], reset)
    return out


def _draw(seeds: np.ndarray, reset: str) -> np.ndarray:
    from mjx_pusht.task.pcg64 import Streams

    st = Streams(seeds)
    if reset == "chapter":
        return np.stack([st.uniform(*TEE_X_RANGE), st.uniform(*TEE_Y_RANGE), st.uniform(*TEE_YAW_RANGE)], axis=-1)
    tee = np.stack([st.uniform(-TASK_TEE_HALF, TASK_TEE_HALF), st.uniform(-TASK_TEE_HALF, TASK_TEE_HALF),
                    st.uniform(-np.pi, np.pi)], axis=-1)
    pusher = np.empty((len(seeds), 2))
    todo = np.arange(len(seeds))
    for k in range(PUSHER_TRIES):  # try k for the rows whose earlier tries all landed on the T
        xy = np.stack([st.uniform(-TASK_PUSHER_HALF, TASK_PUSHER_HALF), st.uniform(-TASK_PUSHER_HALF, TASK_PUSHER_HALF)], -1)
        clear = (distance_to_tee(xy, tee[todo]) > PUSHER_RADIUS + CLEARANCE) | (k == PUSHER_TRIES - 1)
        pusher[todo[clear]] = xy[clear]
        todo = todo[~clear]
        if not len(todo):
            break
        st = st.subset(~clear)
    return np.concatenate([tee, pusher], axis=-1)


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
        """(N, nq) start qpos: qpos0 with the tee at each pose and the pusher south of it
        (or, for (N, 5) starts, where columns 3 and 4 put it).

        Only the tee's own joints are seeded; in split-tee the stem body keeps its
        qpos0, which is exactly why that T cannot be set down as one piece.
        """
        qpos = np.tile(model.qpos0, (len(poses), 1))
        if self.tee is not None:
            qpos[:, list(self.tee)] = poses[:, :3]
        else:
            a = self.tee_free
            qpos[:, a], qpos[:, a + 1] = poses[:, 0], poses[:, 1]
            qpos[:, a + 3] = np.cos(poses[:, 2] / 2)
            qpos[:, a + 4 : a + 6] = 0.0
            qpos[:, a + 6] = np.sin(poses[:, 2] / 2)
        if poses.shape[1] >= 5:
            qpos[:, list(self.pusher)] = poses[:, 3:5]
        else:
            qpos[:, self.pusher[1]] = PUSHER_START_Y
        return qpos
