"""The top view in plain JAX ops: a third renderer of the pixels `CpuRenderer` and `WarpRenderer` draw.

MJX-Warp's ray tracer is an XLA FFI call bound to one device's render context, which XLA cannot partition:
under `jax.shard_map` it cannot run (compiling it there crashed XLA on 2 x H200), so a data-parallel program
that renders (a pixel student's fit over several GPUs) had no renderer. This one is elementwise array arithmetic, so it
runs wherever JAX runs, sharded or not, vmapped over any batch without buffers sized for it.

It needs no ray tracing because the view (`view_model`) is flat: an orthographic camera looking straight down,
ambient light only (each face its own rgba), no blending, each pixel the scene at the pixel's centre. So a pixel
shows the colour of the geom whose surface is highest at its centre, or the background where none covers it. The
geoms it draws are those both renderers draw (WarpRenderer's `enabled_geom_groups=[0]`, alpha above 0): planes
(finite where their size says), boxes, cylinders, capsules and spheres, each upright (turned about z only, checked
once at construction, so a box's or a cylinder's visible surface is its flat top and its footprint a rectangle or a
disk). The camera's pose and extent are MuJoCo's own (mj_forward of the view).

`state_images(env)` is `pixels.state_images(env, n)` on this renderer, for any batch: a learner renders its
minibatches through it inside a shard_map'd fit. Tests (tests/test_raster.py): MuJoCo C's image but for under 1e-3 of
the pixels, each on an edge (the bound MJX-Warp meets against it); MJX-Warp's, the same bound (measured: no pixel).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.render.pixels import CAMERA, IMAGE_SIZE, PixelsError, Target, _check_size, view_model

# What MuJoCo C's OpenGL renderer and MJX-Warp's ray tracer both show where no geom is, measured: black
BACKGROUND = (0, 0, 0)
_G = mujoco.mjtGeom
_SHAPES = {int(_G.mjGEOM_PLANE): "plane", int(_G.mjGEOM_BOX): "box", int(_G.mjGEOM_CYLINDER): "cylinder",
           int(_G.mjGEOM_CAPSULE): "capsule", int(_G.mjGEOM_SPHERE): "sphere"}


class Raster:
    """One world's pose -> (size, size, 3) uint8, the image CpuRenderer and WarpRenderer draw of it, in JAX ops.

    `__call__(d, goal=None)` takes what WarpRenderer takes (one world's mjx.Data, any impl: only its qpos is read)
    and `draw(geom_xpos, geom_xmat, goal=None)` the geoms' world poses after kinematics; both are pure and jittable,
    and vmap over any batch. `goal`: None, the scene's target; else this world's goal (3,) (`Target`)."""

    def __init__(self, model, size: int = IMAGE_SIZE):
        from mujoco import mjx

        self.size = _check_size(size)
        self.view = view = view_model(model, self.size)
        self.target = Target(view)
        host = mujoco.MjData(view)
        mujoco.mj_forward(view, host)
        shown = [g for g in range(view.ngeom) if view.geom_group[g] == 0 and view.geom_rgba[g, 3] > 0]
        for g in shown:
            _check_drawable(view, host, g)
        self.ids = np.array(shown, int)
        self.shapes = [_SHAPES[int(view.geom_type[g])] for g in shown]
        # a plane draws as a box of no height, infinite along an axis whose size is 0 (MuJoCo's convention)
        self.geom_size = view.geom_size[self.ids].copy()
        planes = np.array([shape == "plane" for shape in self.shapes], bool)
        self.geom_size[planes, :2] = np.where(self.geom_size[planes, :2] > 0, self.geom_size[planes, :2], np.inf)
        self.geom_size[planes, 2] = 0
        # a byte as MJX-Warp writes it (truncated, clamped); view_model put every level a quarter above its byte
        rgb = np.clip(np.floor(view.geom_rgba[self.ids, :3] * 255), 0, 255)
        self.palette = np.vstack([rgb, BACKGROUND]).astype(np.uint8)  # the last entry: no geom
        self.centres = _pixel_centres(view, host, self.size)
        # MJX's JAX kinematics (plain ops, like the rest) of a copy with no collisions: kinematics needs none, and
        # MJX's JAX impl refuses pairs it cannot collide (the cylinder pusher against a box)
        still = copy.deepcopy(view)
        still.geom_contype[:], still.geom_conaffinity[:] = 0, 0
        self.mx = mjx.put_model(still)
        self.d0 = mjx.make_data(self.mx)

    def __call__(self, d, goal=None):
        """One world's image of `d.qpos`, the target at `goal` (None: the scene's)."""
        return self.draw(*self.poses(d.qpos), goal)

    def poses(self, qpos):
        """One world's geom positions and orientations at `qpos`, by MJX's kinematics (a stepped Data holds the
        pose before its step, as WarpRenderer says)."""
        from mujoco import mjx

        k = mjx.kinematics(self.mx, self.d0.replace(qpos=qpos.astype(self.d0.qpos.dtype)))
        return k.geom_xpos, k.geom_xmat

    def draw(self, geom_xpos, geom_xmat, goal=None):
        """One world's image from its (ngeom, 3) geom positions and (ngeom, 3, 3) (or (ngeom, 9)) orientations."""
        import jax.numpy as jnp

        xmat = geom_xmat.reshape(-1, 3, 3)
        if goal is not None:
            xpos, tmat = self.target.at(goal.astype(geom_xpos.dtype), jnp)
            geom_xpos, xmat = geom_xpos.at[self.target.ids].set(xpos), xmat.at[self.target.ids].set(tmat)
        dtype = geom_xpos.dtype
        px, py = (jnp.asarray(c, dtype) for c in self.centres)
        best = jnp.full(px.shape, len(self.ids), jnp.int32)  # the background's palette entry
        top = jnp.full(px.shape, -jnp.inf, dtype)
        for i, (g, shape) in enumerate(zip(self.ids, self.shapes)):
            pos, rot, (a, b, c) = geom_xpos[g], xmat[g], map(float, self.geom_size[i])
            dx, dy = px - pos[0], py - pos[1]
            lx, ly = rot[0, 0] * dx + rot[1, 0] * dy, rot[0, 1] * dx + rot[1, 1] * dy  # in the geom's own frame
            if shape in ("box", "plane"):
                covers, height = (jnp.abs(lx) <= a) & (jnp.abs(ly) <= b), pos[2] + c
            elif shape == "cylinder":
                covers, height = lx * lx + ly * ly <= a * a, pos[2] + b
            else:  # a sphere, or an upright capsule's upper cap: the surface's height over this pixel
                rho2 = lx * lx + ly * ly
                covers = rho2 <= a * a
                height = pos[2] + (b if shape == "capsule" else 0) + jnp.sqrt(jnp.maximum(a * a - rho2, 0))
            # strictly higher wins: at a tie the lower index stays (ties here are between geoms of one colour)
            wins = covers & (height > top)
            best, top = jnp.where(wins, i, best), jnp.where(wins, height, top)
        return jnp.asarray(self.palette)[best].reshape(self.size, self.size, 3)


def _check_drawable(view, host, g: int) -> None:
    """One line for a geom this renderer would draw wrongly: an unsupported shape, translucent, or not upright
    (its z axis off the world's, or on a body that can turn about another axis: a ball, free or tilted hinge joint
    on it or above it)."""
    name = view.geom(g).name or f"#{g}"
    if int(view.geom_type[g]) not in _SHAPES:
        kind = mujoco.mjtGeom(view.geom_type[g]).name.removeprefix("mjGEOM_").lower()
        raise PixelsError(f"the raster renderer draws planes, boxes, cylinders, capsules and spheres; geom {name} "
                          f"is of type {kind}")
    if view.geom_rgba[g, 3] < 1:
        raise PixelsError(f"the raster renderer draws opaque geoms; geom {name} has alpha {view.geom_rgba[g, 3]:g}")
    if not np.allclose(host.geom_xmat[g].reshape(3, 3)[:, 2], (0, 0, 1), atol=1e-9):
        raise PixelsError(f"the raster renderer draws upright geoms (turned about z only); geom {name} is tilted")
    body = view.geom_bodyid[g]
    while body:
        for j in range(view.body_jntadr[body], view.body_jntadr[body] + view.body_jntnum[body]):
            kind = mujoco.mjtJoint(view.jnt_type[j])  # (a numpy int is never `in` a tuple of the enum's members)
            tilted_hinge = kind == mujoco.mjtJoint.mjJNT_HINGE and not np.allclose(abs(host.xaxis[j, 2]), 1, atol=1e-9)
            if kind in (mujoco.mjtJoint.mjJNT_BALL, mujoco.mjtJoint.mjJNT_FREE) or tilted_hinge:
                raise PixelsError(f"the raster renderer draws upright geoms (turned about z only); geom {name} can "
                                  f"turn about another axis (joint {view.joint(j).name or j})")
        body = view.body_parentid[body]


def _pixel_centres(view, host, size: int):
    """The world (x, y) at each pixel's centre, row by row from the top: the camera's orthographic frame (cam_fovy
    metres high, square) on MuJoCo's own camera pose, which must look straight down."""
    cam = view.camera(CAMERA).id
    axes = host.cam_xmat[cam].reshape(3, 3)  # columns: the camera's right, up and backward directions
    if view.cam_projection[cam] != mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC or not np.allclose(axes[:, 2], (0, 0, 1)):
        raise PixelsError("the raster renderer draws an orthographic camera looking straight down")
    half = view.cam_fovy[cam] / 2
    steps = (np.arange(size) + 0.5) / size * 2 * half - half  # pixel centres across the frame, left to right
    u, v = np.meshgrid(steps, -steps)  # rows run down the image, up the camera's frame
    xy = host.cam_xpos[cam, :2] + u.reshape(-1, 1) * axes[:2, 0] + v.reshape(-1, 1) * axes[:2, 1]
    return xy[:, 0], xy[:, 1]


def state_images(env):
    """`PushTEnv.images` on this renderer: a jittable function from (n, 5) observation states (pusher x, y, tee x,
    y, yaw) and optional goals (n, 3) to env's (n, size, size, 3) images, for any n and on any backend's env."""
    import jax

    if not env.pixels or env.layout.tee is None:
        raise ConfigError("images() needs an env with pixels and the tee on slide and hinge joints")
    raster, q0 = Raster(env.model, env.pixels), np.asarray(env.model.qpos0, np.float64)

    def images(states, goals=None):  # goals None: vmap maps an empty tree, each world gets None
        return jax.vmap(lambda q, g: raster.draw(*raster.poses(q), g))(env.layout.qpos_of_state(q0, states), goals)

    return images
