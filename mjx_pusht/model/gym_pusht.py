"""gym-pusht's frame and scene: the `gym-pusht` variant of the PushT scene, and its pixel units.

gym-pusht (0.1.8, pymunk) works in a 512 x 512 pixel frame, y pointing down (the image's rows),
with its T (`add_tee`, scale 30) posed by its body origin, the middle of the bar's top edge,
and the goal T at (256, 256, pi/4). Its T is the chapter's T to the millimetre (bar 120 x 30,
stem 30 x 90; the pusher radius 15), so one pixel is one millimetre here.

The variant keeps this project's world frame, the goal T at the origin with yaw 0 (so coverage,
keypoints and invariants are the task's own functions), and places gym-pusht's walls, camera and
colours around it: the frame is a reflection (pixel y points down), so a yaw is minus gym-pusht's
angle measured from the goal's. `to_world` / `to_px` and `pose_to_world` / `pose_to_px` are the
whole map, exact both ways.
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
# gym-pusht's keypoints: each shape's vertices as pymunk stores them (bar, then stem), in its T's frame
KEYPOINTS_LOCAL_PX = np.array([(-60, 0), (60, 0), (60, 30), (-60, 30), (-15, 30), (15, 30), (15, 120), (-15, 120)],
                              np.float64)
# pygame's named colours gym-pusht draws with; a T and the agent are filled 1.2x lighter than their outline
COLOURS = {
    "background": (255, 255, 255), "wall": (211, 211, 211), "goal": (144, 238, 144),
    "tee_edge": (119, 136, 153), "tee": (142, 163, 183), "agent_edge": (65, 105, 225), "agent": (78, 126, 255),
}


def _rot(a, xp=np):
    c, s = xp.cos(a), xp.sin(a)
    return c, s


def to_world(p, xp=np):
    """gym-pusht pixel positions (..., 2) to world (..., 2) metres."""
    gx, gy, gt = GOAL_PX
    c, s = math.cos(-gt), math.sin(-gt)
    dx, dy = p[..., 0] - gx, p[..., 1] - gy
    lx, ly = c * dx - s * dy, s * dx + c * dy  # in the goal T's frame, pixels
    return xp.stack([lx * PX, (ORIGIN_PX - ly) * PX], axis=-1)


def to_px(w, xp=np):
    """World positions (..., 2) in metres to gym-pusht pixels (..., 2)."""
    gx, gy, gt = GOAL_PX
    c, s = math.cos(gt), math.sin(gt)
    lx, ly = w[..., 0] / PX, ORIGIN_PX - w[..., 1] / PX
    return xp.stack([c * lx - s * ly + gx, s * lx + c * ly + gy], axis=-1)


def velocity_to_px(v, xp=np):
    """World velocities (..., 2), m/s, to pixels per second."""
    gt = GOAL_PX[2]
    c, s = math.cos(gt), math.sin(gt)
    lx, ly = v[..., 0] / PX, -v[..., 1] / PX
    return xp.stack([c * lx - s * ly, s * lx + c * ly], axis=-1)


def pose_to_world(origin, angle, xp=np):
    """gym-pusht block poses (its body origin (..., 2) in pixels, angle (...)) to tee poses (..., 3)."""
    c, s = _rot(angle, xp)
    bar = xp.stack([origin[..., 0] - s * ORIGIN_PX, origin[..., 1] + c * ORIGIN_PX], axis=-1)
    xy = to_world(bar, xp)
    return xp.concatenate([xy, (GOAL_PX[2] - angle)[..., None]], axis=-1)


def pose_to_px(pose, xp=np):
    """Tee poses (..., 3) to gym-pusht's (body origin (..., 2) in pixels, angle (...) in [0, 2 pi))."""
    angle = (GOAL_PX[2] - pose[..., 2]) % (2 * math.pi)
    bar = to_px(pose[..., :2], xp)
    c, s = _rot(angle, xp)
    origin = xp.stack([bar[..., 0] + s * ORIGIN_PX, bar[..., 1] - c * ORIGIN_PX], axis=-1)
    return origin, angle


def keypoints_px(origin, angle, xp=np):
    """gym-pusht's `environment_state`: (..., 16) its T's 8 vertices in pixels, in its order."""
    c, s = _rot(angle, xp)
    k = xp.asarray(KEYPOINTS_LOCAL_PX, dtype=origin.dtype)
    x = c[..., None] * k[:, 0] - s[..., None] * k[:, 1] + origin[..., 0:1]
    y = s[..., None] * k[:, 0] + c[..., None] * k[:, 1] + origin[..., 1:2]
    return xp.reshape(xp.stack([x, y], axis=-1), x.shape[:-1] + (16,))


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


# -- the scene's regions ------------------------------------------------------------------------
def _rgba(name: str) -> str:
    r, g, b = COLOURS[name]
    return f"{r / 255:.6f} {g / 255:.6f} {b / 255:.6f} 1"


def _box_in_px(name: str, x0, x1, y0, y1, z: float, hz: float, rgba: str, extra: str = "") -> str:
    """A box spanning pixels [x0, x1] x [y0, y1], placed in the world (its axes along the pixel frame's)."""
    cx, cy = to_world(np.array([(x0 + x1) / 2, (y0 + y1) / 2]))
    yaw = GOAL_PX[2]  # the pixel x axis points along world yaw pi/4
    q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    return (f'<geom name="{name}" type="box" pos="{cx:.6f} {cy:.6f} {z}" quat="{q[0]:.9f} 0 0 {q[3]:.9f}" '
            f'size="{(x1 - x0) / 2 * PX:.6f} {(y1 - y0) / 2 * PX:.6f} {hz}" rgba="{rgba}"{extra}/>')


def ground_mjcf() -> str:
    """A white table and gym-pusht's four walls, inner faces at 7 and 504 px. Each wall is 40 px thick,
    outward (out of the picture but for its inner 7 px), so a fast block cannot tunnel through it."""
    lo, hi = WALL_INNER_PX
    out = 40.0
    rgba = _rgba("wall")
    walls = [("wall_n", lo - out, hi + out, lo - out, lo), ("wall_s", lo - out, hi + out, hi, hi + out),
             ("wall_w", lo - out, lo, lo, hi), ("wall_e", hi, hi + out, lo, hi)]
    parts = [f'<geom name="table" type="plane" size="0.45 0.45 0.1" rgba="{_rgba("background")}" '
             'contype="0" conaffinity="0"/>']
    parts += [_box_in_px(n, x0, x1, y0, y1, 0.03, 0.03, rgba) for n, x0, x1, y0, y1 in walls]
    return "\n    " + "\n    ".join(parts)


# pygame draws a point at pixel (x, y) rounded, whose centre is (x + 0.5, y + 0.5) in the image's continuous
# frame, and fills a polygon's boundary pixels: gym-pusht's pictures sit half a pixel right and down of its
# geometry, and its goal is half a pixel fuller each side. The camera and the goal's visual geoms do the same.
PYGAME_OFFSET_PX = 0.5


def camera_mjcf() -> str:
    """Looking straight down on the 512-px frame, orthographic, image right along pixel x, down along pixel y."""
    cx, cy = to_world(np.array([256.0 - PYGAME_OFFSET_PX, 256.0 - PYGAME_OFFSET_PX]))
    gt = GOAL_PX[2]
    right = (math.cos(gt), math.sin(gt))
    up = (-math.sin(gt), math.cos(gt))
    return (f'\n    <camera name="top" pos="{cx:.6f} {cy:.6f} 1.0" xyaxes="{right[0]:.9f} {right[1]:.9f} 0 '
            f'{up[0]:.9f} {up[1]:.9f} 0" projection="orthographic" fovy="{512 * PX}"/>')


# The T: the chapter's geoms (physics unchanged) in gym-pusht's lighter fill, over visual-only
# outlines 2 px wider each side (gym-pusht draws each edge with a 4 px line); the block collides
# with the walls and the pusher (bits 1 and 2).
TEE_MJCF = """
    <body name="tee" pos="0 0 0.0152">
      <joint name="tee_x" type="slide" axis="1 0 0" damping="4" frictionloss="1.2"/>
      <joint name="tee_y" type="slide" axis="0 1 0" damping="4" frictionloss="1.2"/>
      <joint name="tee_yaw" type="hinge" axis="0 0 1" damping="0.02" frictionloss="0.006"/>
      <geom name="tee_bar" type="box" size="0.06 0.015 0.015" pos="0 0 0" rgba="{fill}" mass="0.06" conaffinity="3"/>
      <geom name="tee_stem" type="box" size="0.015 0.045 0.015" pos="0 -0.06 0" rgba="{fill}" mass="0.045" conaffinity="3"/>
      <geom name="tee_bar_edge" type="box" size="0.062 0.017 0.014" pos="0 0 0" rgba="{edge}" contype="0" conaffinity="0" mass="0"/>
      <geom name="tee_stem_edge" type="box" size="0.017 0.047 0.014" pos="0 -0.06 0" rgba="{edge}" contype="0" conaffinity="0" mass="0"/>
    </body>"""

# gym-pusht's agent is kinematic: nothing stops it, walls included. Here it is a heavy (10 kg)
# cylinder that touches only the block (bit 2), drawn under the T as gym-pusht draws it.
PUSHER_MASS = 10.0
PUSHER_MJCF = """
    <body name="pusher" pos="0 0 0.0152">
      <joint name="pusher_x" type="slide" axis="1 0 0"/>
      <joint name="pusher_y" type="slide" axis="0 1 0"/>
      <geom name="pusher_tip" type="cylinder" size="0.015 0.012" rgba="{edge}" mass="{mass}" contype="2" conaffinity="2"/>
      <geom name="pusher_face" type="cylinder" size="0.011 0.0121" rgba="{fill}" contype="0" conaffinity="0" mass="0"/>
    </body>"""

# gym-pusht's PD law, acceleration = kp (target - position) - kv velocity with kp = 100, kv = 20,
# as a position servo on each axis (force = mass x that acceleration). Under MuJoCo's Euler
# integrator the free pusher then moves exactly as gym-pusht's agent: v += dt a; x += dt v.
KP, KV = 100.0, 20.0
ACTUATOR_MJCF = """
    <position name="pusher_px" joint="pusher_x" kp="{kp}" kv="{kv}"/>
    <position name="pusher_py" joint="pusher_y" kp="{kp}" kv="{kv}"/>"""


EXTRA_GEOMS = 3  # the T's two outlines and the agent's lighter face: drawn, never collided


def regions() -> dict[str, str]:
    """The variant's MJCF regions, by the names scene.SCENE_TEMPLATE fills."""
    from mjx_pusht.model.scene import target_mjcf

    return {
        "option": 'integrator="Euler"',
        "camera": camera_mjcf(),
        "ground": ground_mjcf(),
        "target": target_mjcf(_rgba("goal"), grow=PYGAME_OFFSET_PX * PX),
        "tee": TEE_MJCF.format(fill=_rgba("tee"), edge=_rgba("tee_edge")),
        "pusher": PUSHER_MJCF.format(edge=_rgba("agent_edge"), fill=_rgba("agent"), mass=PUSHER_MASS),
        "actuator": ACTUATOR_MJCF.format(kp=KP * PUSHER_MASS, kv=KV * PUSHER_MASS),
    }
