"""The `gym-pusht` variant of the PushT scene: gym-pusht's walls, camera, colours, agent and physics, as MJCF regions.

scene.scene_xml swaps these regions into the chapter's template; the numbers come from
gym-pusht's frame (model/gym_pusht.py), and the target T from model/target.py, which the
chapter's scene formats too. Nothing here imports the scene.

The physics is gym-pusht's pymunk space (gym_pusht/envs/pusht.py, 0.1.8) in MuJoCo terms, all in
the MJCF, so every backend steps it with the same control step (docs/dropin-physics.md measures it):
- `space.damping = 0`: pymunk scales a body's velocity by damping ** dt before each step's contact
  solve, so the block keeps no velocity between 0.01 s steps. Here each of the T's dofs has damping
  d = mass / dt, applied explicitly (`eulerdamp` off): MuJoCo's Euler step v' = v + dt M^-1 (f - d v)
  then starts every step's contact solve from zero velocity. That needs a diagonal mass matrix,
  so the T turns about its centre of gravity (the yaw hinge sits there, layout.QposLayout.anchor).
- Frictionless contacts (gym-pusht sets `friction` on its Body objects, which pymunk does not read;
  a Shape's friction defaults to 0): condim 1 on every geom that collides.
- Pymunk's contact solve with restitution 0 leaves no approach velocity, and its position bias
  moves penetration out at 1 - collision_bias ** dt = 6.1% a step: a direct solref of damping
  1 / dt and stiffness 0.0613 / dt^2 on near-hard contacts (impedance 0.9999) does both.
- The T: mass 1, moment 2 * moment_for_poly(1, bar) = 3000 px^2 about its centre of gravity, the
  mean of its two boxes' centroids, 45 px down its axis from gym-pusht's origin.
- The agent is KINEMATIC (infinite mass: contacts cannot slow it): here 1e6 kg, a million times the T,
  on position servos that give gym-pusht's PD law; it collides through a sphere of radius 15 px at
  the T's mid-height (a circle in the plane: MuJoCo's cylinder-box path returned a face normal at a
  corner), drawn as gym-pusht draws its agent by two visual cylinders.
"""

from __future__ import annotations

import math

import numpy as np

from mjx_pusht.model.gym_pusht import AGENT_RADIUS_PX, COG_PX, COLOURS, GOAL_PX, KP, KV, ORIGIN_PX, PX, \
    WALL_INNER_PX, to_world
from mjx_pusht.model.target import target_mjcf

DT = 0.01  # the scene's timestep (scene.SCENE_TEMPLATE), gym-pusht's dt
TEE_MASS = 1.0  # kg, gym-pusht's `mass = 1`
TEE_MOMENT = 3000.0 * PX * PX  # kg m^2: pymunk.moment_for_poly(1, vertices1) is 1500 px^2, added twice
COG_Y = -(COG_PX - ORIGIN_PX) * PX  # the centre of gravity in the T's frame: 30 px from the bar's centre, stemwards
# pymunk's contact bias: 1 - collision_bias ** dt of a penetration is moved out each step (collision_bias
# = (1 - 0.1) ** 60, pymunk's default), as the stiffness of a constraint whose damping removes the approach
# velocity in one step (MuJoCo's direct solref "-stiffness -damping")
BIAS = 1.0 - (1.0 - 0.1) ** (60 * DT)
CONTACT = f'condim="1" solref="-{BIAS / DT**2:.4f} -{1 / DT:.1f}" solimp="0.9999 0.9999 0.001"'


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
    """gym-pusht's four walls, inner faces at 7 and 504 px, and its white table between them.

    The walls collide: each 40 px thick, outward (out of the picture but for its inner 7 px), so a fast block
    cannot tunnel through it. They are not drawn (group 3): the picture's wall-grey border is a floor plane
    under a white box spanning the walls' inner faces, the "table". The frame is turned 45 degrees from the
    world's axes, so each long wall box's world-aligned bounding box covered much of the picture, and MJX-Warp's
    ray tracer tested it for most rays: measured on one H100 at 65,536 96 x 96 images, the render took 141 ms
    with the four walls drawn, 85 ms without (benchmarks/render_geoms.py, docs/notebook/lead.md). One white box
    has the walls' inner faces as its edges, so the pictures keep their borders."""
    lo, hi = WALL_INNER_PX
    out = 40.0
    rgba = _rgba("wall")
    walls = [("wall_n", lo - out, hi + out, lo - out, lo), ("wall_s", lo - out, hi + out, hi, hi + out),
             ("wall_w", lo - out, lo, lo, hi), ("wall_e", hi, hi + out, lo, hi)]
    parts = [f'<geom name="floor" type="plane" size="0.45 0.45 0.1" pos="0 0 -0.004" rgba="{rgba}" '
             'contype="0" conaffinity="0"/>',
             _box_in_px("table", lo, hi, lo, hi, -0.001, 0.001, _rgba("background"), ' contype="0" conaffinity="0"')]
    parts += [_box_in_px(n, x0, x1, y0, y1, 0.03, 0.03, rgba, ' group="3" ' + CONTACT) for n, x0, x1, y0, y1 in walls]
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


# The T: the chapter's geoms in gym-pusht's lighter fill, over visual-only outlines 2 px wider each side
# (gym-pusht draws each edge with a 4 px line), with gym-pusht's mass and moment; the block collides with
# the walls and the pusher (bits 1 and 2). Each dof's damping is its mass over dt (see the module's docstring).
TEE_MJCF = """
    <body name="tee" pos="0 0 0.0152">
      <inertial pos="0 {cog_y} 0" mass="{mass}" diaginertia="{moment} {moment} {moment}"/>
      <joint name="tee_x" type="slide" axis="1 0 0" damping="{d_xy}"/>
      <joint name="tee_y" type="slide" axis="0 1 0" damping="{d_xy}"/>
      <joint name="tee_yaw" type="hinge" axis="0 0 1" pos="0 {cog_y} 0" damping="{d_yaw}"/>
      <geom name="tee_bar" type="box" size="0.06 0.015 0.015" pos="0 0 0" rgba="{fill}" conaffinity="3" {contact}/>
      <geom name="tee_stem" type="box" size="0.015 0.045 0.015" pos="0 -0.06 0" rgba="{fill}" conaffinity="3" {contact}/>
      <geom name="tee_bar_edge" type="box" size="0.062 0.017 0.014" pos="0 0 0" rgba="{edge}" contype="0" conaffinity="0" mass="0"/>
      <geom name="tee_stem_edge" type="box" size="0.017 0.047 0.014" pos="0 -0.06 0" rgba="{edge}" contype="0" conaffinity="0" mass="0"/>
    </body>"""

# gym-pusht's agent is kinematic: nothing stops it, walls included. Here a heavy body that touches only
# the block (bit 2) through `pusher_tip`, a sphere kept out of the pictures (group 3); gym-pusht's circle
# is drawn under the T by the two visual cylinders.
PUSHER_MASS = 1e6
PUSHER_MJCF = """
    <body name="pusher" pos="0 0 0.0152">
      <joint name="pusher_x" type="slide" axis="1 0 0"/>
      <joint name="pusher_y" type="slide" axis="0 1 0"/>
      <geom name="pusher_tip" type="sphere" size="{radius}" rgba="{edge}" mass="{mass}" contype="2" conaffinity="2" group="3" {contact}/>
      <geom name="pusher_edge" type="cylinder" size="{radius} 0.012" rgba="{edge}" contype="0" conaffinity="0" mass="0"/>
      <geom name="pusher_face" type="cylinder" size="0.011 0.0121" rgba="{fill}" contype="0" conaffinity="0" mass="0"/>
    </body>"""

# gym-pusht's PD law (frame.KP, frame.KV) as a position servo on each axis (force = mass x that
# acceleration). Under MuJoCo's Euler integrator the free pusher then moves exactly as gym-pusht's
# agent: v += dt a; x += dt v.
ACTUATOR_MJCF = """
    <position name="pusher_px" joint="pusher_x" kp="{kp}" kv="{kv}"/>
    <position name="pusher_py" joint="pusher_y" kp="{kp}" kv="{kv}"/>"""


EXTRA_GEOMS = 5  # the T's two outlines, the agent's two cylinders and the floor under the table: drawn, never collided


def regions() -> dict[str, str]:
    """The variant's MJCF regions, by the names scene.SCENE_TEMPLATE fills."""
    return {
        "option": 'integrator="Euler"',
        "flag": ' eulerdamp="disable"',  # the T's damping is its velocity reset: explicit, as the solver sees it
        "camera": camera_mjcf(),
        "ground": ground_mjcf(),
        "target": target_mjcf(_rgba("goal"), grow=PYGAME_OFFSET_PX * PX),
        "tee": TEE_MJCF.format(fill=_rgba("tee"), edge=_rgba("tee_edge"), cog_y=f"{COG_Y:.6f}", mass=TEE_MASS,
                               moment=f"{TEE_MOMENT:.6g}", d_xy=f"{TEE_MASS / DT:.6g}",
                               d_yaw=f"{TEE_MOMENT / DT:.6g}", contact=CONTACT),
        "pusher": PUSHER_MJCF.format(edge=_rgba("agent_edge"), fill=_rgba("agent"), mass=PUSHER_MASS,
                                     radius=f"{AGENT_RADIUS_PX * PX:.6f}", contact=CONTACT),
        "actuator": ACTUATOR_MJCF.format(kp=KP * PUSHER_MASS, kv=KV * PUSHER_MASS),
    }
