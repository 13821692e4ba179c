"""The `gym-pusht` variant of the PushT scene: gym-pusht's walls, camera, colours and agent, as MJCF regions.

scene.scene_xml swaps these regions into the chapter's template; the numbers come from
gym-pusht's frame (model/gym_pusht.py), and the target T from model/target.py, which the
chapter's scene formats too. Nothing here imports the scene.
"""

from __future__ import annotations

import math

import numpy as np

from mjx_pusht.model.gym_pusht import COLOURS, GOAL_PX, KP, KV, PX, WALL_INNER_PX, to_world
from mjx_pusht.model.target import target_mjcf


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

# gym-pusht's PD law (frame.KP, frame.KV) as a position servo on each axis (force = mass x that
# acceleration). Under MuJoCo's Euler integrator the free pusher then moves exactly as gym-pusht's
# agent: v += dt a; x += dt v.
ACTUATOR_MJCF = """
    <position name="pusher_px" joint="pusher_x" kp="{kp}" kv="{kv}"/>
    <position name="pusher_py" joint="pusher_y" kp="{kp}" kv="{kv}"/>"""


EXTRA_GEOMS = 3  # the T's two outlines and the agent's lighter face: drawn, never collided


def regions() -> dict[str, str]:
    """The variant's MJCF regions, by the names scene.SCENE_TEMPLATE fills."""
    return {
        "option": 'integrator="Euler"',
        "camera": camera_mjcf(),
        "ground": ground_mjcf(),
        "target": target_mjcf(_rgba("goal"), grow=PYGAME_OFFSET_PX * PX),
        "tee": TEE_MJCF.format(fill=_rgba("tee"), edge=_rgba("tee_edge")),
        "pusher": PUSHER_MJCF.format(edge=_rgba("agent_edge"), fill=_rgba("agent"), mass=PUSHER_MASS),
        "actuator": ACTUATOR_MJCF.format(kp=KP * PUSHER_MASS, kv=KV * PUSHER_MASS),
    }
