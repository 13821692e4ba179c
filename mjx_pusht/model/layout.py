"""Where the tee and the pusher live in a compiled model's qpos: the one reader every backend uses."""

from __future__ import annotations

import dataclasses
import functools

import mujoco
import numpy as np

PUSHER_START_Y = -0.25  # the chapter's pusher start (m), for starts that place only the tee


def _take(qpos, idx: tuple):
    """qpos[..., idx] as a new array. Host addresses in a row are copied as a slice (the same values as the
    gather, without building an index array: an env's step reads these several times)."""
    run = _run(idx) if isinstance(qpos, np.ndarray) else None
    return qpos[..., run].copy() if run is not None else qpos[..., list(idx)]


@functools.lru_cache(maxsize=16)
def _run(idx: tuple) -> slice | None:
    """The slice of consecutive addresses `idx`, or None where they are not consecutive."""
    return slice(idx[0], idx[0] + len(idx)) if idx == tuple(range(idx[0], idx[0] + len(idx))) else None


@dataclasses.dataclass(frozen=True)
class QposLayout:
    """Where the tee's pose and the pusher live in qpos, found by joint name.

    Planar variants read (x, y, yaw) from three joints; the free-tee variant reads
    position and a quaternion from one free joint. A tee whose yaw hinge sits off its origin
    (`anchor`, in the tee's frame: the gym-pusht variant turns its T about its centre of gravity)
    keeps the hinge point in tee_x, tee_y (less the anchor), and its pose is still the origin's:
    origin = (tee_x, tee_y) + anchor - R(yaw) anchor.
    """

    tee: tuple[int, int, int] | None  # planar: qpos addresses of tee_x, tee_y, tee_yaw
    tee_free: int | None  # free-tee: qpos address of the free joint
    pusher: tuple[int, int]
    nq: int
    anchor: tuple[float, float] | None = None  # planar: the yaw hinge's point in the tee's frame, if not (0, 0)

    @classmethod
    def of(cls, model: mujoco.MjModel) -> "QposLayout":
        def adr(name: str) -> int:
            return int(model.joint(name).qposadr[0])

        names = {model.joint(j).name for j in range(model.njnt)}
        anchor = None
        if "tee_free" in names:
            tee, free = None, adr("tee_free")
        else:
            tee, free = (adr("tee_x"), adr("tee_y"), adr("tee_yaw")), None
            ax, ay = (float(v) for v in model.joint("tee_yaw").pos[:2])
            anchor = (ax, ay) if (ax, ay) != (0.0, 0.0) else None
        return cls(tee, free, (adr("pusher_x"), adr("pusher_y")), int(model.nq), anchor)

    def _swing(self, yaw, xp):
        """anchor - R(yaw) anchor: where the origin goes, relative to the hinge's joints, as the T turns."""
        ax, ay = self.anchor
        c, s = xp.cos(yaw), xp.sin(yaw)
        return ax - (c * ax - s * ay), ay - (s * ax + c * ay)

    def tee_pose(self, qpos):
        """(..., 3) tee (x, y, yaw) from (..., nq) qpos; NumPy or JAX arrays alike."""
        xp = qpos.__array_namespace__()
        if self.tee is not None:
            pose = _take(qpos, self.tee)
            if self.anchor is None:
                return pose
            dx, dy = self._swing(pose[..., 2], xp)
            if isinstance(pose, np.ndarray):  # the same sums, added in place into the new array: no stack
                pose[..., 0] += dx
                pose[..., 1] += dy
                return pose
            return xp.stack([pose[..., 0] + dx, pose[..., 1] + dy, pose[..., 2]], axis=-1)
        a = self.tee_free
        w, x, y, z = (qpos[..., a + 3 + k] for k in range(4))
        yaw = xp.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        return xp.stack([qpos[..., a], qpos[..., a + 1], yaw], axis=-1)

    def pusher_xy(self, qpos):
        return _take(qpos, self.pusher)

    def qpos_of_state(self, qpos0: np.ndarray, state):
        """(..., nq) qpos from (..., 5) observation states (pusher x, y, tee x, y, yaw; `observe`'s order):
        the state's values in the tee's and the pusher's joints, qpos0's elsewhere; built by stacking, so it is
        exact and jittable in either namespace (the tee on slide and hinge joints only)."""
        xp = state.__array_namespace__()
        if self.anchor is not None:
            dx, dy = self._swing(state[..., 4], xp)
            state = xp.stack([state[..., 0], state[..., 1], state[..., 2] - dx, state[..., 3] - dy, state[..., 4]], axis=-1)
        source = {**{c: 2 + i for i, c in enumerate(self.tee)}, **{c: i for i, c in enumerate(self.pusher)}}
        return xp.stack([state[..., source[c]] if c in source else xp.full(state.shape[:-1], qpos0[c], dtype=state.dtype)
                         for c in range(len(qpos0))], axis=-1)

    def initial_qpos(self, model: mujoco.MjModel, poses: np.ndarray) -> np.ndarray:
        """(N, nq) start qpos: qpos0 with the tee at each pose and the pusher south of it
        (or, for (N, 5) starts, where columns 3 and 4 put it).

        Only the tee's own joints are seeded; in split-tee the stem body keeps its
        qpos0, which is exactly why that T cannot be set down as one piece.
        """
        qpos = np.tile(model.qpos0, (len(poses), 1))
        if self.tee is not None:
            qpos[:, list(self.tee)] = poses[:, :3]
            if self.anchor is not None:
                dx, dy = self._swing(poses[:, 2], np)
                qpos[:, self.tee[0]] -= dx
                qpos[:, self.tee[1]] -= dy
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
