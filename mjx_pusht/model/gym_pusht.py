"""gym-pusht's frame: its pixel units, poses, keypoints, colours and resets, mapped to this project's world.

gym-pusht (0.1.8, pymunk) works in a 512 x 512 pixel frame, y pointing down (the image's rows),
with its T (`add_tee`, scale 30) posed by its body origin, the middle of the bar's top edge,
and the goal T at (256, 256, pi/4). Its T is the chapter's T to the millimetre (bar 120 x 30,
stem 30 x 90; the pusher radius 15), so one pixel is one millimetre here.

The variant keeps this project's world frame, the goal T at the origin with yaw 0 (so coverage,
keypoints and invariants are the task's own functions), and places gym-pusht's walls, camera and
colours around it: the frame is a reflection (pixel y points down), so a yaw is minus gym-pusht's
angle measured from the goal's. `to_world` / `to_px` and `pose_to_world` / `pose_to_px` are the
whole map, exact both ways. The variant's MJCF, built from these numbers, is model/gym_pusht_scene.py.
"""

from __future__ import annotations

import math

import numpy as np

PX = 0.001  # metres per gym-pusht pixel
GOAL_PX = (256.0, 256.0, math.pi / 4)  # gym-pusht's goal: T origin (pixels) and angle
ORIGIN_PX = 15.0  # the chapter's T origin (bar centre) lies 15 px from gym-pusht's (the bar's top edge)
COG_PX = 45.0  # pymunk's centre of gravity of gym-pusht's T, on its axis (the mean of its two shapes' centroids)
WALL_INNER_PX = (7.0, 504.0)  # walls: segments at 5 and 506 with radius 2
AGENT_RADIUS_PX = 15.0
KP, KV = 100.0, 20.0  # gym-pusht's PD law for its agent: acceleration = KP (target - position) - KV velocity
# gym-pusht's keypoints: each shape's vertices as pymunk stores them (bar, then stem), in its T's frame
KEYPOINTS_LOCAL_PX = np.array([(-60, 0), (60, 0), (60, 30), (-60, 30), (-15, 30), (15, 30), (15, 120), (-15, 120)],
                              np.float64)
# pygame's named colours gym-pusht draws with; a T and the agent are filled 1.2x lighter than their outline
COLOURS = {
    "background": (255, 255, 255), "wall": (211, 211, 211), "goal": (144, 238, 144),
    "tee_edge": (119, 136, 153), "tee": (142, 163, 183), "agent_edge": (65, 105, 225), "agent": (78, 126, 255),
}


def _stack(xp, parts):
    """xp.stack(parts, axis=-1). On the host, the parts are copied into a new array: the same values, without
    np.stack's Python-level checks, which cost more than the arithmetic for one env's step (the drop-in)."""
    parts = [np.asarray(p) for p in parts] if xp is np else parts
    if xp is not np or any(p.shape != parts[0].shape for p in parts):
        return xp.stack(parts, axis=-1)  # (and np.stack's own error for parts of different shapes)
    out = np.empty(parts[0].shape + (len(parts),), np.result_type(*parts))
    for i, p in enumerate(parts):
        out[..., i] = p
    return out


def _rot(a, xp=np):
    c, s = xp.cos(a), xp.sin(a)
    return c, s


def to_world(p, xp=np):
    """gym-pusht pixel positions (..., 2) to world (..., 2) metres."""
    gx, gy, gt = GOAL_PX
    c, s = math.cos(-gt), math.sin(-gt)
    dx, dy = p[..., 0] - gx, p[..., 1] - gy
    lx, ly = c * dx - s * dy, s * dx + c * dy  # in the goal T's frame, pixels
    return _stack(xp, [lx * PX, (ORIGIN_PX - ly) * PX])


def to_px(w, xp=np):
    """World positions (..., 2) in metres to gym-pusht pixels (..., 2)."""
    gx, gy, gt = GOAL_PX
    c, s = math.cos(gt), math.sin(gt)
    lx, ly = w[..., 0] / PX, ORIGIN_PX - w[..., 1] / PX
    return _stack(xp, [c * lx - s * ly + gx, s * lx + c * ly + gy])


def velocity_to_px(v, xp=np):
    """World velocities (..., 2), m/s, to pixels per second."""
    gt = GOAL_PX[2]
    c, s = math.cos(gt), math.sin(gt)
    lx, ly = v[..., 0] / PX, -v[..., 1] / PX
    return _stack(xp, [c * lx - s * ly, s * lx + c * ly])


def pose_to_world(origin, angle, xp=np):
    """gym-pusht block poses (its body origin (..., 2) in pixels, angle (...)) to tee poses (..., 3)."""
    c, s = _rot(angle, xp)
    bar = _stack(xp, [origin[..., 0] - s * ORIGIN_PX, origin[..., 1] + c * ORIGIN_PX])
    xy = to_world(bar, xp)
    return xp.concatenate([xy, (GOAL_PX[2] - angle)[..., None]], axis=-1)


def pose_to_px(pose, xp=np):
    """Tee poses (..., 3) to gym-pusht's (body origin (..., 2) in pixels, angle (...) in [0, 2 pi))."""
    angle = (GOAL_PX[2] - pose[..., 2]) % (2 * math.pi)
    bar = to_px(pose[..., :2], xp)
    c, s = _rot(angle, xp)
    origin = _stack(xp, [bar[..., 0] + s * ORIGIN_PX, bar[..., 1] - c * ORIGIN_PX])
    return origin, angle


def keypoints_px(origin, angle, xp=np):
    """gym-pusht's `environment_state`: (..., 16) its T's 8 vertices in pixels, in its order."""
    c, s = _rot(angle, xp)
    k = xp.asarray(KEYPOINTS_LOCAL_PX, dtype=origin.dtype)
    x = c[..., None] * k[:, 0] - s[..., None] * k[:, 1] + origin[..., 0:1]
    y = s[..., None] * k[:, 0] + c[..., None] * k[:, 1] + origin[..., 1:2]
    return xp.reshape(_stack(xp, [x, y]), x.shape[:-1] + (16,))


def legacy_state_to_world(state) -> np.ndarray:
    """gym-pusht's reset state [agent x, y, block x, y, angle] (pixels) to [tee x, y, yaw, pusher x, y].

    gym-pusht keeps a legacy quirk (its docstring warns of it): it sets the block's position with
    the angle still 0, then the angle, which pymunk turns about the T's centre of gravity (45 px
    down its axis), so the block's origin ends up at position + (0, 45) - R(angle) (0, 45), not
    at the position given. This reproduces it, so the same state gives the same start.
    """
    s = np.atleast_2d(np.asarray(state, np.float64))
    a = s[:, 4]
    origin = np.stack([s[:, 2] + np.sin(a) * COG_PX, s[:, 3] + COG_PX - np.cos(a) * COG_PX], axis=-1)
    tee = pose_to_world(origin, a)
    return np.concatenate([tee, to_world(s[:, 0:2])], axis=-1)


def reset_state(seed: int) -> np.ndarray:
    """gym-pusht's random reset for `seed`: the five draws its `reset` makes from the env's generator
    (gymnasium seeds it as `np.random.default_rng(seed)`), in its order."""
    rng = np.random.default_rng(seed)
    return np.array([rng.integers(50, 450), rng.integers(50, 450), rng.integers(100, 400), rng.integers(100, 400),
                     rng.uniform(-np.pi, np.pi)], np.float64)
