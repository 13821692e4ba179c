"""Read back the kinematic tree MuJoCo compiled, and check it against the authored one.

The XML is intent; the compiled model is what MuJoCo built. A scene that still
compiles but grants other DOFs runs and lies quietly, so every entry point checks
the compiled tree against the expected tree below before a single step.
"""

from __future__ import annotations

import dataclasses
import json

import mujoco

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.model.gym_pusht_scene import EXTRA_GEOMS

JOINT_TYPE_NAME = {
    int(mujoco.mjtJoint.mjJNT_FREE): "free",
    int(mujoco.mjtJoint.mjJNT_BALL): "ball",
    int(mujoco.mjtJoint.mjJNT_SLIDE): "slide",
    int(mujoco.mjtJoint.mjJNT_HINGE): "hinge",
}


@dataclasses.dataclass(frozen=True)
class Tree:
    """The structural facts of a compiled scene (world body excluded from `bodies`)."""

    bodies: tuple[tuple[str, str], ...]  # (body, parent) in body order
    joints: tuple[tuple[str, str], ...]  # (joint, type) in qpos order
    nq: int
    nv: int
    nu: int
    n_geoms: int

    @property
    def n_bodies(self) -> int:
        return len(self.bodies)

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def joint_types(self) -> list[str]:
        return [t for _, t in self.joints]

    def to_dict(self) -> dict:
        return {
            "bodies": [{"name": b, "parent": p} for b, p in self.bodies],
            "joints": [{"name": j, "type": t} for j, t in self.joints],
            "joint_types": self.joint_types,
            "n_bodies": self.n_bodies,
            "n_joints": self.n_joints,
            "n_geoms": self.n_geoms,
            "nq": self.nq,
            "nv": self.nv,
            "nu": self.nu,
        }

    def describe(self) -> str:
        """The chapter's printout: counts, each body with its parent, joint types in qpos order."""
        lines = [
            f"kinematic tree: {self.n_bodies} bodies under worldbody, {self.n_joints} joints, "
            f"nq={self.nq} nv={self.nv} nu={self.nu}, {self.n_geoms} geoms"
        ]
        lines += [f"  body '{b}' <- parent '{p}'" for b, p in self.bodies]
        lines.append(f"joint types (in qpos order): {self.joint_types}")
        return "\n".join(lines)


def read_tree(model: mujoco.MjModel) -> Tree:
    """The tree as compiled, read from the model (not the XML)."""
    bodies = tuple(
        (model.body(i).name, model.body(int(model.body_parentid[i])).name) for i in range(1, model.nbody)
    )
    order = sorted(range(model.njnt), key=lambda j: int(model.jnt_qposadr[j]))
    joints = tuple((model.joint(j).name, JOINT_TYPE_NAME[int(model.jnt_type[j])]) for j in order)
    return Tree(bodies, joints, int(model.nq), int(model.nv), int(model.nu), int(model.ngeom))


def _planar(prefix: str) -> tuple[tuple[str, str], ...]:
    return ((f"{prefix}_x", "slide"), (f"{prefix}_y", "slide"), (f"{prefix}_yaw", "hinge"))


_PUSHER_JOINTS = (("pusher_x", "slide"), ("pusher_y", "slide"))
_N_GEOMS = 10  # table, 4 walls, 2 target, 2 tee, pusher

# The trees the chapter authors, written out by hand: the reference a compiled
# model must match.
EXPECTED_TREES: dict[str, Tree] = {
    "none": Tree(
        bodies=(("target", "world"), ("tee", "world"), ("pusher", "world")),
        joints=_planar("tee") + _PUSHER_JOINTS,
        nq=5, nv=5, nu=2, n_geoms=_N_GEOMS,
    ),
    "split-tee": Tree(
        bodies=(("target", "world"), ("tee", "world"), ("tee_stem_body", "world"), ("pusher", "world")),
        joints=_planar("tee") + _planar("stem") + _PUSHER_JOINTS,
        nq=8, nv=8, nu=2, n_geoms=_N_GEOMS,
    ),
    "free-tee": Tree(
        bodies=(("target", "world"), ("tee", "world"), ("pusher", "world")),
        joints=(("tee_free", "free"),) + _PUSHER_JOINTS,
        nq=9, nv=8, nu=2, n_geoms=_N_GEOMS,
    ),
}


class TreeMismatch(MjxPushtError, ValueError):
    """The compiled tree is not the authored one."""


def tree_differences(got: Tree, want: Tree) -> list[str]:
    """Each difference between two trees, as a short human-readable phrase."""
    diffs = []
    for field in ("n_bodies", "n_joints", "nq", "nv", "nu", "n_geoms"):
        g, w = getattr(got, field), getattr(want, field)
        if g != w:
            diffs.append(f"{field} is {g}, expected {w}")
    if got.bodies != want.bodies:
        extra = [f"{b}<-{p}" for b, p in got.bodies if (b, p) not in want.bodies]
        missing = [f"{b}<-{p}" for b, p in want.bodies if (b, p) not in got.bodies]
        diffs.append(f"bodies differ (unexpected: {extra or 'none'}; missing: {missing or 'none'})")
    if got.joints != want.joints:
        extra = [f"{j}:{t}" for j, t in got.joints if (j, t) not in want.joints]
        missing = [f"{j}:{t}" for j, t in want.joints if (j, t) not in got.joints]
        diffs.append(
            f"joints differ (unexpected: {extra or 'none'}; missing: {missing or 'none'}; "
            f"types in qpos order {got.joint_types}, expected {want.joint_types})"
        )
    return diffs


def check_tree(model: mujoco.MjModel, break_it: str, variant: str = "chapter") -> Tree:
    """Return the compiled tree, or raise TreeMismatch naming every difference."""
    got, want = read_tree(model), EXPECTED_TREES[break_it]
    if variant == "gym-pusht":  # the same tree; EXTRA_GEOMS more that are only drawn
        want = dataclasses.replace(want, n_geoms=want.n_geoms + EXTRA_GEOMS)
    diffs = tree_differences(got, want)
    if diffs:
        raise TreeMismatch(f"compiled tree is not the authored '{break_it}' scene: " + "; ".join(diffs))
    return got


def tree_json(tree: Tree) -> str:
    return json.dumps(tree.to_dict(), indent=2, sort_keys=True)
