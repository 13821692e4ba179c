"""The PushT scene, authored in regions as the chapter builds it, and its variants.

The numbers here are the chapter's spec: sizes, masses, damping, gains, timestep.
Each region is a string so a variant swaps one region and leaves the rest alone.
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import mujoco

from mjx_pusht import boundary
from mjx_pusht.errors import ConfigError
from mjx_pusht.model import gym_pusht_scene
from mjx_pusht.model.target import target_mjcf
from mjx_pusht.model.tree import check_tree

BreakMode = Literal["none", "split-tee", "free-tee"]
PusherShape = Literal["cylinder", "capsule"]
BREAK_MODES: tuple[str, ...] = ("none", "split-tee", "free-tee")
PUSHER_SHAPES: tuple[str, ...] = ("cylinder", "capsule")

# The table is a collision-free backdrop: planar friction is emulated with joint
# damping and frictionloss on the block, which keeps the push quasi-static.
GROUND_MJCF = """
    <geom name="table" type="plane" size="0.45 0.45 0.1" rgba="0.90 0.90 0.92 1" contype="0" conaffinity="0"/>
    <geom name="wall_n" type="box" pos="0 0.41 0.03" size="0.43 0.02 0.03" rgba="0.6 0.6 0.6 1"/>
    <geom name="wall_s" type="box" pos="0 -0.41 0.03" size="0.43 0.02 0.03" rgba="0.6 0.6 0.6 1"/>
    <geom name="wall_e" type="box" pos=" 0.41 0 0.03" size="0.02 0.43 0.03" rgba="0.6 0.6 0.6 1"/>
    <geom name="wall_w" type="box" pos="-0.41 0 0.03" size="0.02 0.43 0.03" rgba="0.6 0.6 0.6 1"/>"""

_PLANAR_JOINTS = """
      <joint name="{p}_x" type="slide" axis="1 0 0" damping="4" frictionloss="1.2"/>
      <joint name="{p}_y" type="slide" axis="0 1 0" damping="4" frictionloss="1.2"/>
      <joint name="{p}_yaw" type="hinge" axis="0 0 1" damping="0.02" frictionloss="0.006"/>"""

_BAR = '<geom name="tee_bar" type="box" size="0.06 0.015 0.015" pos="0 0 0" rgba="0.45 0.5 0.95 1" mass="0.06"/>'

# One body, two geoms: sharing a body IS the weld; the planar joint set grants
# exactly x, y and yaw, so the block cannot tip into 3D.
TEE_WELDED_MJCF = f"""
    <body name="tee" pos="0 0 0.0152">{_PLANAR_JOINTS.format(p="tee")}
      {_BAR}
      <geom name="tee_stem" type="box" size="0.015 0.045 0.015" pos="0 -0.06 0" rgba="0.45 0.5 0.95 1" mass="0.045"/>
    </body>"""

# Break It: the same geoms in two bodies, each with its own planar joints.
# The reset seeds only the bar's joints, so the T settles already split.
TEE_SPLIT_MJCF = f"""
    <body name="tee" pos="0 0 0.0152">{_PLANAR_JOINTS.format(p="tee")}
      {_BAR}
    </body>
    <body name="tee_stem_body" pos="0 -0.06 0.0152">{_PLANAR_JOINTS.format(p="stem")}
      <geom name="tee_stem" type="box" size="0.015 0.045 0.015" pos="0 0 0" rgba="0.95 0.5 0.45 1" mass="0.045"/>
    </body>"""

# Exercise 1: the wrong DOFs granted. A free joint gives the welded T all six
# DOFs; with the table's collision off nothing holds it on the plane.
TEE_FREE_MJCF = f"""
    <body name="tee" pos="0 0 0.0152">
      <freejoint name="tee_free"/>
      {_BAR}
      <geom name="tee_stem" type="box" size="0.015 0.045 0.015" pos="0 -0.06 0" rgba="0.45 0.5 0.95 1" mass="0.045"/>
    </body>"""

_TEE_REGIONS = {"none": TEE_WELDED_MJCF, "split-tee": TEE_SPLIT_MJCF, "free-tee": TEE_FREE_MJCF}

# The pusher cannot rotate (no hinge); its velocity servos take m/s targets.
PUSHER_MJCF = """
    <body name="pusher" pos="0 0 0.02">
      <joint name="pusher_x" type="slide" axis="1 0 0" damping="0.5"/>
      <joint name="pusher_y" type="slide" axis="0 1 0" damping="0.5"/>
      <geom name="pusher_tip" type="{shape}" size="0.015 0.02" rgba="0.9 0.4 0.35 1" mass="0.2"/>
    </body>"""

ACTUATOR_MJCF = """
    <velocity name="pusher_vx" joint="pusher_x" kv="20" ctrlrange="-1 1" forcerange="-30 30"/>
    <velocity name="pusher_vy" joint="pusher_y" kv="20" ctrlrange="-1 1" forcerange="-30 30"/>"""

TARGET_MJCF = target_mjcf("0.35 0.8 0.4 0.5")

# Instrumentation, not physics: the two tee geoms' world positions as sensors, so
# every backend (including mujoco.rollout, which returns only state and
# sensordata) reads the weld gap from MuJoCo's own kinematics.
SENSOR_MJCF = """
    <framepos name="bar_pos" objtype="geom" objname="tee_bar"/>
    <framepos name="stem_pos" objtype="geom" objname="tee_stem"/>"""

# autoreset off: MuJoCo would otherwise silently reset a diverged state to qpos0
# and keep stepping; we want the NaN, so the non-finite flag can catch it.
CAMERA_MJCF = """
    <camera name="top" pos="0 0 1.0" quat="1 0 0 0" fovy="50"/>"""

SCENE_TEMPLATE = """<mujoco model="pusht">
  <option timestep="0.01" {option}>
    <flag autoreset="disable"{flag}/>
  </option>
  <worldbody>{camera}{ground}{target}{tee}{pusher}
  </worldbody>
  <actuator>{actuator}
  </actuator>
  <sensor>{sensor}
  </sensor>
</mujoco>
"""


@dataclasses.dataclass(frozen=True)
class SceneSpec:
    """Which scene to author: the break mode, the pusher's collision shape, and the variant.

    `variant="gym-pusht"` is gym-pusht's PushT (model/gym_pusht_scene.py): its walls, goal, camera
    and colours, its agent's PD law on position servos, and its pymunk physics in MJCF (a T that
    keeps no velocity between steps, frictionless contacts, an agent nothing pushes back); the same
    joint names and sensors, so every backend, invariant and env runs it unchanged.
    """

    break_it: str = "none"
    pusher: str = "cylinder"
    variant: str = "chapter"

    def __post_init__(self) -> None:
        boundary.OneOf(tuple(BREAK_MODES))("break mode", self.break_it)  # an array is refused, not compared
        boundary.OneOf(tuple(PUSHER_SHAPES))("pusher shape", self.pusher)  # an array is refused, not compared
        boundary.OneOf(tuple(VARIANTS))("scene variant", self.variant)  # an array is refused, not compared
        if self.variant != "chapter" and (self.break_it, self.pusher) != ("none", "cylinder"):
            raise ConfigError(f"the {self.variant} scene is the welded T with a cylinder pusher "
                              "(break modes and pusher shapes are the chapter's)")


VARIANTS: tuple[str, ...] = ("chapter", "gym-pusht")


def scene_xml(spec: SceneSpec) -> str:
    """The MJCF document for `spec`, assembled region by region."""
    regions = dict(
        option='integrator="implicitfast"',
        flag="",
        camera=CAMERA_MJCF,
        ground=GROUND_MJCF,
        target=TARGET_MJCF,
        tee=_TEE_REGIONS[spec.break_it],
        pusher=PUSHER_MJCF.format(shape=spec.pusher),
        actuator=ACTUATOR_MJCF,
        sensor=SENSOR_MJCF,
    )
    if spec.variant == "gym-pusht":
        regions.update(gym_pusht_scene.regions())
    return SCENE_TEMPLATE.format(**regions)


def compile_xml(xml: str) -> mujoco.MjModel:
    """Compile MJCF text; MuJoCo raises here, before any step, on a malformed scene."""
    return mujoco.MjModel.from_xml_string(xml)


def build_model(spec: SceneSpec, *, validate: bool = True) -> mujoco.MjModel:
    """Compile the scene and, by default, check the compiled tree against the authored one."""
    model = compile_xml(scene_xml(spec))
    if validate:
        check_tree(model, spec.break_it, spec.variant)
    return model
