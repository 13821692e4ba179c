"""Which collision function each side runs for each geom pair of the scene, read from the libraries.

MuJoCo C routes box-box to its primitive `mjc_BoxBox` whatever the native-CCD flag says;
MuJoCo Warp routes it to its general GJK/EPA path unless the model's `mjDSBL_NATIVECCD`
bit is set, which switches it to its primitive `box_box`. `MjxConfig.match_c_colliders`
sets that bit on the model MJX-Warp receives (never on the CPU reference's), so the tee
meets the walls through the same kind of function on both sides.

- MuJoCo C keeps its table in C (`mjCOLLISIONFUNC`), out of Python's reach, so its side is
  found by experiment: the pair is put in contact and collided with native CCD on and off.
  The same contacts both ways means a primitive function that no CCD setting reaches;
  different contacts mean the general convex path (`mjc_Convex`, native CCD or libccd).
- MuJoCo Warp: its `MJ_COLLISION_TABLE` (primitive or convex), with the override its
  narrowphase applies for `mjDSBL_NATIVECCD`, and the primitive's name from `_PRIMITIVE_COLLISIONS`.
- MJX-JAX: the function its `_COLLISION_FUNC` wraps (it runs the capsule pusher).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from mjx_pusht.errors import MjxPushtError

GEOM_NAME = {int(v): k.removeprefix("mjGEOM_").lower() for k, v in mujoco.mjtGeom.__members__.items()}
NATIVECCD = int(mujoco.mjtDisableBit.mjDSBL_NATIVECCD)


@dataclasses.dataclass(frozen=True)
class PairColliders:
    geoms: tuple[str, str]
    types: tuple[str, str]
    mujoco_c: str
    mjx_warp: str
    mjx_jax: str  # for the same pair in the capsule-pusher scene MJX-JAX runs


def _touching_qpos(model: mujoco.MjModel, g1: int, g2: int) -> np.ndarray | None:
    """qpos where geoms g1 and g2 overlap by 2 mm, moving the one on joints toward the other."""
    from mjx_pusht.model.layout import QposLayout

    layout = QposLayout.of(model)
    if layout.tee is None:
        return None
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    pusher = model.body("pusher").id
    moving, fixed = (g1, g2) if model.geom_bodyid[g1] == pusher or model.body_weldid[model.geom_bodyid[g2]] == 0 else (g2, g1)
    p_fixed = data.geom_xpos[fixed, :2]
    # push along the axis that points from the fixed geom toward the workspace's centre (walls),
    # or toward -y (a tee geom met by the pusher from the south)
    axis = -np.sign(p_fixed) * (np.abs(p_fixed) == np.abs(p_fixed).max()) if np.abs(p_fixed).max() > 0.2 else np.array([0.0, -1.0])
    k = int(np.argmax(np.abs(axis)))
    reach = model.geom_size[fixed][k] + (model.geom_size[moving][0] if model.geom_bodyid[moving] == pusher
                                         else model.geom_size[moving][k]) - 0.002
    target = p_fixed + axis * reach
    qpos = model.qpos0.copy()
    offset = data.geom_xpos[moving, :2] - data.xpos[model.geom_bodyid[moving], :2]
    adr = list(layout.pusher) if model.geom_bodyid[moving] == pusher else list(layout.tee[:2])
    qpos[adr] = target - offset
    if model.geom_bodyid[moving] != pusher:
        qpos[list(layout.pusher)] = (0.0, -0.3)  # keep the pusher out of the way
    return qpos


def contacts_c(model: mujoco.MjModel, qpos: np.ndarray, disable: int = 0) -> list[tuple]:
    """MuJoCo C's contacts at qpos: (geom1, geom2, pos, dist), sorted."""
    m = model
    saved = m.opt.disableflags
    m.opt.disableflags = saved | disable
    try:
        d = mujoco.MjData(m)
        d.qpos[:] = qpos
        mujoco.mj_forward(m, d)
        return sorted((int(c.geom[0]), int(c.geom[1]), tuple(np.round(c.pos, 12)), float(c.dist)) for c in d.contact[: d.ncon])
    finally:
        m.opt.disableflags = saved


def mujoco_c_kind(model: mujoco.MjModel, g1: int, g2: int) -> str:
    qpos = _touching_qpos(model, g1, g2)
    if qpos is None:
        return "not probed"
    on = [c for c in contacts_c(model, qpos) if {c[0], c[1]} == {g1, g2}]
    off = [c for c in contacts_c(model, qpos, NATIVECCD) if {c[0], c[1]} == {g1, g2}]
    if not on:
        return "not probed (no contact found)"
    if on == off:
        return f"primitive (identical {len(on)} contacts with native CCD on and off)"
    return f"general convex, mjc_Convex ({len(on)} contacts; they change with the CCD implementation)"


def mjx_warp_kind(t1: int, t2: int, disableflags: int) -> str:
    from mjx_pusht.model import mjx_private

    wd, wprim, wtypes = mjx_private.warp_collision()
    CollisionType, GeomType = wtypes.CollisionType, wtypes.GeomType

    key = (GeomType(min(t1, t2)), GeomType(max(t1, t2)))
    kind = wd.MJ_COLLISION_TABLE.get(key)
    if key == (GeomType.BOX, GeomType.BOX) and disableflags & NATIVECCD:
        kind = CollisionType.PRIMITIVE  # the override wd._narrowphase applies
    if kind == CollisionType.PRIMITIVE:
        fn = wprim._PRIMITIVE_COLLISIONS.get(key)
        return f"primitive {getattr(fn, '__name__', fn).removesuffix('_wrapper')}"
    if kind == CollisionType.CONVEX:
        return "general convex, GJK/EPA (ccd)"
    return "none"


def mjx_jax_kind(t1: int, t2: int) -> str:
    from mjx_pusht.model import mjx_private

    jd, jtypes = mjx_private.jax_collision()
    GeomType = jtypes.GeomType

    fn = jd._COLLISION_FUNC.get((GeomType(min(t1, t2)), GeomType(max(t1, t2))))
    if fn is None:
        return "none (MJX-JAX cannot collide this pair)"
    inner = [c.cell_contents for c in (fn.__closure__ or ()) if callable(c.cell_contents)]
    return inner[0].__name__ if inner else fn.__name__


def collision_pairs(model: mujoco.MjModel) -> list[tuple[str, str]]:
    """Geom pairs the collision filter lets touch: different bodies, not both static, masks overlap."""
    pairs = []
    for i in range(model.ngeom):
        for j in range(i + 1, model.ngeom):
            bi, bj = int(model.geom_bodyid[i]), int(model.geom_bodyid[j])
            if bi == bj or (model.body_weldid[bi] == 0 and model.body_weldid[bj] == 0):
                continue
            if not (model.geom_contype[i] & model.geom_conaffinity[j] or model.geom_contype[j] & model.geom_conaffinity[i]):
                continue
            pairs.append((model.geom(i).name, model.geom(j).name))
    return pairs


def collider_table(break_it: str = "none", match_c_colliders: bool = True, pusher: str = "cylinder") -> list[PairColliders]:
    """Every collidable geom pair of the scene with `pusher`'s shape and the function each side calls for it
    (MJX-Warp's table is read from MuJoCo Warp itself, so warp-lang must be installed; MJX-JAX's column is always the
    capsule it substitutes)."""
    from mjx_pusht.model.scene import SceneSpec, build_model

    try:
        import warp  # noqa: F401
    except ImportError:
        raise MjxPushtError("the collider table reads MuJoCo Warp's own tables, which need warp-lang: "
                            "pip install 'mjx-pusht[warp]'") from None

    model = build_model(SceneSpec(break_it, pusher))
    capsule = build_model(SceneSpec(break_it, "capsule"))
    flags = int(model.opt.disableflags) | (NATIVECCD if match_c_colliders else 0)
    out = []
    for a, b in collision_pairs(model):
        g1, g2 = model.geom(a).id, model.geom(b).id
        t1, t2 = int(model.geom_type[g1]), int(model.geom_type[g2])
        c1, c2 = int(capsule.geom_type[capsule.geom(a).id]), int(capsule.geom_type[capsule.geom(b).id])
        out.append(PairColliders((a, b), (GEOM_NAME[t1], GEOM_NAME[t2]), mujoco_c_kind(model, g1, g2),
                                 mjx_warp_kind(t1, t2, flags), f"{mjx_jax_kind(c1, c2)} ({GEOM_NAME[c1]}-{GEOM_NAME[c2]})"))
    return out


def describe(rows: list[PairColliders]) -> str:
    w = max(len(f"{r.geoms[0]} - {r.geoms[1]}") for r in rows)
    lines = [f"{'geom pair':<{w}}  {'types':<16}  MuJoCo C | MJX-Warp | MJX-JAX"]
    for r in rows:
        lines.append(f"{r.geoms[0] + ' - ' + r.geoms[1]:<{w}}  {r.types[0] + '-' + r.types[1]:<16}  "
                     f"{r.mujoco_c} | {r.mjx_warp} | {r.mjx_jax}")
    return "\n".join(lines)
