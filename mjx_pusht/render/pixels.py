"""Pixel observations: the scene from above, the same image from MuJoCo C's renderer and MJX-Warp's.

Both renderers look through the scene's `top` camera, made orthographic over the walled
workspace, so pixel (column, row) of a size x size image is `task.to_pixels(xy, size)`: the
frame gym-pusht's 512-pixel window uses, at any size. The authored scene is left as the
chapter wrote it; `view_model` derives what the pixels show from it:

- the camera is orthographic (a PushT image has no perspective; gym-pusht draws in 2D);
- the headlight is ambient only, so every face shows its own rgba (flat colours, as gym-pusht
  draws them) and OpenGL's lighting cannot differ from the ray tracer's;
- the translucent target is drawn opaque in the colour it shows over the table: MJX-Warp's
  ray tracer has no alpha blending, and the block always lies above the target anyway;
- no multisampling: each pixel is the scene at the pixel's centre, as the ray tracer sees it;
- each colour sits a quarter step above an 8-bit level, so OpenGL (which rounds) and the ray
  tracer (which truncates) write the same byte.

`CpuRenderer` renders (N, nq) positions with MuJoCo's OpenGL renderer (headless through EGL or
OSMesa: `MUJOCO_GL`); `WarpRenderer` renders one world's `mjx.Data` inside a vmapped, jitted
program (MJX-Warp's batched ray tracer), so images never leave the device per step.
"""

from __future__ import annotations

import copy
import os
import sys

import numpy as np

from mjx_pusht.errors import ConfigError, MjxPushtError
from mjx_pusht.task.rules import WORKSPACE_HALF

CAMERA = "top"
IMAGE_SIZE = 96  # Diffusion Policy's and gym-pusht's observation size


class PixelsError(MjxPushtError, RuntimeError):
    """A renderer that cannot run here (no GL, no GPU, no Warp): one line that says what to install or set."""


def view_model(model, size: int = IMAGE_SIZE):
    """A copy of the scene's model as the pixels show it (see the module's docstring); physics untouched."""
    import mujoco

    view = copy.deepcopy(model)
    cam = view.camera(CAMERA).id
    if view.cam_projection[cam] != mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC:  # the chapter's camera
        view.cam_projection[cam] = mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC
        view.cam_fovy[cam] = 2 * WORKSPACE_HALF  # orthographic fovy is the frame's height in metres
    # else a variant's camera, authored orthographic over its own frame (gym-pusht's 512 px)
    table_rgb = view.geom_rgba[view.geom("table").id, :3].copy()
    for name in ("target_bar", "target_stem"):
        rgba = view.geom_rgba[view.geom(name).id]
        a = rgba[3]
        rgba[:3] = a * rgba[:3] + (1 - a) * table_rgb
        rgba[3] = 1.0
    # OpenGL rounds colour * 255 to a byte and MJX-Warp truncates it: a quarter level above the byte
    # OpenGL would write gives both that byte
    view.geom_rgba[:, :3] = (np.round(view.geom_rgba[:, :3] * 255) + 0.25) / 255
    view.vis.headlight.ambient[:] = 1.0
    view.vis.headlight.diffuse[:] = 0.0
    view.vis.headlight.specular[:] = 0.0
    view.vis.quality.offsamples = 0
    # No light of these scenes casts a shadow (they have none; the headlight casts none), yet each render context
    # MuJoCo makes allocates a shadowsize^2 shadow map, 4096^2 by default: ~70 MB a context with Mesa, never drawn
    # into. LeRobot's vector of 500 drop-in envs, a context each, went past 24 GB for it (notebook lead18)
    if not view.light_castshadow.any():
        view.vis.quality.shadowsize = 0
    view.vis.global_.offwidth = max(int(view.vis.global_.offwidth), size)
    view.vis.global_.offheight = max(int(view.vis.global_.offheight), size)
    return view


class Target:
    """Where the target T's geoms are drawn for an episode's goal (task/goals.py). The scene places them at its
    goal, the origin with yaw 0, on the world body; a goal (x, y, yaw) is a rigid motion of that pose, so the
    geoms' world poses are that motion applied to the scene's. Only the view moves them (a renderer overwrites the
    geoms' poses after kinematics): they collide with nothing, so the physics is the same wherever they are drawn."""

    NAMES = ("target_bar", "target_stem")

    def __init__(self, view):
        import mujoco

        self.ids = np.array([view.geom(name).id for name in self.NAMES])
        data = mujoco.MjData(view)
        mujoco.mj_kinematics(view, data)
        self.xpos, self.xmat = data.geom_xpos[self.ids].copy(), data.geom_xmat[self.ids].reshape(-1, 3, 3).copy()

    def at(self, goal, xp=np):
        """(k, 3) positions and (k, 3, 3) orientations of the target geoms for one goal (3,) (x, y, yaw)."""
        c, s = xp.cos(goal[2]), xp.sin(goal[2])
        zero, one = xp.zeros_like(c), xp.ones_like(c)
        rot = xp.stack([xp.stack([c, -s, zero]), xp.stack([s, c, zero]), xp.stack([zero, zero, one])])
        shift = xp.stack([goal[0], goal[1], zero])
        return xp.asarray(self.xpos, rot.dtype) @ rot.T + shift, rot @ xp.asarray(self.xmat, rot.dtype)


def _check_size(size: int) -> int:
    if int(size) != size or not 8 <= size <= 2048:
        raise ConfigError(f"image size must be an integer from 8 to 2048 pixels, got {size}")
    return int(size)


_EGL_FROM_PARENT = False  # set in a forked child whose parent had initialised EGL


def _after_fork_in_child() -> None:
    """EGL cannot render in a forked child once its parent initialised it: Mesa's rendering threads are not
    forked, and the child's first draw waits for them forever (gymnasium's AsyncVectorEnv under `fork` hung).
    Remember it here, so the child's first renderer refuses in one line instead."""
    global _EGL_FROM_PARENT
    egl = sys.modules.get("mujoco.egl")
    _EGL_FROM_PARENT = _EGL_FROM_PARENT or (egl is not None and getattr(egl, "EGL_DISPLAY", None) is not None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def probe_gl(model) -> None:
    """Open (and free) a renderer of `model` now: a GL that cannot render (MUJOCO_GL a typo, a library missing, glfw
    without a display) is refused in one line before the work whose pictures it would draw, not after it."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # glfw's GLFWError warnings without a display: the one line says it
        CpuRenderer(model, 8)._finalizer()


class CpuRenderer:
    """(N, nq) positions -> (N, size, size, 3) uint8 images, through MuJoCo C's OpenGL renderer.

    Each renderer owns its GL context and makes it current before every GL call it makes, freeing
    included. `mujoco.Renderer` frees its MjrContext on whatever context is current, so closing one
    renderer while another's context was current deleted the other's framebuffer and textures (GL
    object names are per context, and both number theirs from 1): the survivor then rendered
    garbage, differently on every call, with no error. Here the same calls are made in the same
    order as `mujoco.Renderer` makes them (the same pixels), each on this renderer's own context.
    """

    def __init__(self, model, size: int = IMAGE_SIZE):
        import mujoco

        self.size = _check_size(size)
        missing = os.environ.get("MJX_PUSHT_GL_MISSING")
        if missing:  # set aside at import (mjx_pusht/__init__.py): its library is not installed
            lib = {"egl": "EGL (apt-get install libegl1 libgl1-mesa-dri)",
                   "osmesa": "OSMesa (apt-get install libosmesa6)"}[missing]
            raise PixelsError(f"MUJOCO_GL={missing} but {lib} is not installed: install it, or set MUJOCO_GL "
                              "to a GL this machine has (pixels only; everything else runs without GL)")
        invalid = os.environ.get("MJX_PUSHT_GL_INVALID")
        if invalid is not None:  # set aside at import: MuJoCo would not have imported with it
            raise PixelsError(f"MUJOCO_GL={invalid!r} is not a GL MuJoCo knows: set MUJOCO_GL to egl, osmesa or glfw "
                              "(pixels only; everything else runs without GL)")
        if _EGL_FROM_PARENT:
            raise PixelsError("EGL was initialised in this process's parent before it forked, and a forked child "
                              "cannot render with it (it hangs): start workers with 'forkserver' or 'spawn', e.g. "
                              "gym.make_vec(..., vectorization_mode='async', vector_kwargs={'context': 'forkserver'})")
        self.view = view_model(model, self.size)
        self.data = mujoco.MjData(self.view)
        self.target = Target(self.view)
        self._gl = None
        try:
            self._gl, self._mjr = _open_context(self.view, self.size)
        except Exception as e:  # GL missing or unusable: say what to install, not a traceback
            gl = os.environ.get("MUJOCO_GL", "") or "glfw"
            raise PixelsError(
                f"the CPU renderer needs OpenGL without a screen (MUJOCO_GL={gl} failed: {str(e).splitlines()[0]}); "
                "install EGL (Debian: apt-get install libegl1 libgl1-mesa-dri) and set MUJOCO_GL=egl, "
                "or OSMesa (apt-get install libosmesa6) and MUJOCO_GL=osmesa") from None
        self._scene = mujoco.MjvScene(self.view, maxgeom=10000)
        self._option = mujoco.MjvOption()
        self._cam = mujoco.MjvCamera()
        self._cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._cam.fixedcamid = self.view.camera(CAMERA).id
        self._rect = mujoco.MjrRect(0, 0, self.size, self.size)
        self._frame = np.empty((self.size, self.size, 3), np.uint8)
        import atexit
        import weakref

        # Freed when this renderer goes, or at exit before EGL is torn down. MuJoCo terminates the EGL display in
        # an exit hook it registers with the first GL context, and exit hooks run last-registered first:
        # registered here, after the context, this one runs before it. (Once it has run, it holds nothing.)
        self._finalizer = weakref.finalize(self, _free, self._gl, self._mjr)
        self._finalizer.atexit = False
        atexit.register(self._finalizer)

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    def __call__(self, qpos, goals=None) -> np.ndarray:
        """`goals`: None, the scene's target; else each row's goal (N, 3) or one for every row (3,) (`Target`)."""
        import mujoco

        if self.closed:
            raise PixelsError("this renderer was closed")
        qpos = np.atleast_2d(np.asarray(qpos, np.float64))
        if goals is not None:
            goals = np.broadcast_to(np.asarray(goals, np.float64), (len(qpos), 3))
        out = np.empty((len(qpos), self.size, self.size, 3), np.uint8)
        self._gl.make_current()  # another renderer's context may be current: never draw into it
        for i, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.view, self.data)
            if goals is not None:
                xpos, xmat = self.target.at(goals[i])
                self.data.geom_xpos[self.target.ids], self.data.geom_xmat[self.target.ids] = xpos, xmat.reshape(-1, 9)
            mujoco.mj_camlight(self.view, self.data)
            mujoco.mjv_updateScene(self.view, self.data, self._option, None, self._cam,
                                   mujoco.mjtCatBit.mjCAT_ALL.value, self._scene)
            mujoco.mjr_render(self._rect, self._scene, self._mjr)
            mujoco.mjr_readPixels(self._frame, None, self._rect, self._mjr)
            out[i] = self._frame[::-1]  # OpenGL's rows run bottom-up
        return out

    def close(self) -> None:
        """Free this renderer's GL objects on its own context, then the context (idempotent)."""
        self._finalizer()


def _open_context(view, size: int):
    """A GL context of our own, current, and MuJoCo's render context on it, as `mujoco.Renderer` makes them."""
    import mujoco

    gl = mujoco.GLContext(size, size)
    try:
        gl.make_current()
        mjr = mujoco.MjrContext(view, mujoco.mjtFontScale.mjFONTSCALE_150.value)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, mjr)
    except Exception:
        gl.free()
        raise
    return gl, mjr


_STRANDED = []  # render contexts whose GL context is current on another thread: kept, never freed on a wrong one


def _free(gl, mjr) -> None:
    """mjr_freeContext deletes GL objects by name in the current context: make ours current first."""
    try:
        gl.make_current()
    except Exception:  # noqa: BLE001 - current on another thread (EGL_BAD_ACCESS, an EGLError or a RuntimeError, by
        # platform; a renderer made on a worker thread, render.state_images): destroying the context frees its objects,
        _STRANDED.append(mjr)  # and this MjrContext must never free names in whatever context is current here
    else:
        mjr.free()
    gl.free()  # releases this thread's current context; every render makes its own current again


def state_images(env, n: int):
    """`PushTEnv.images` on the cpu backend: a jittable function from (n, 5) observation states to env's (n, size,
    size, 3) images, by MuJoCo C's OpenGL renderer on the host (on MJX: render/raster.py `state_images`)."""
    import jax
    import jax.numpy as jnp

    if not env.pixels or env.layout.tee is None:
        raise ConfigError("images() needs an env with pixels and the tee on slide and hinge joints")
    q0 = np.asarray(env.model.qpos0, np.float64)
    shape = jax.ShapeDtypeStruct((n, env.pixels, env.pixels, 3), jnp.uint8)
    from concurrent.futures import ThreadPoolExecutor

    # JAX calls back on threads of its own, where a GL context cannot be made current (EGL_BAD_ACCESS, or a
    # crash): the images are rendered on one thread of ours, with a renderer of its own
    pool = ThreadPoolExecutor(1, thread_name_prefix="images")
    renderer = pool.submit(CpuRenderer, env.model, env.pixels).result()

    def render(st):
        return pool.submit(renderer, env.layout.qpos_of_state(q0, np.asarray(st, np.float64))).result()

    return lambda states: jax.pure_callback(render, shape, states)


def unpack_rgb(packed):
    """MJX-Warp's packed pixels (uint32: blue in the low byte, then green, then red) to uint8 RGB."""
    import jax.numpy as jnp

    shifts = jnp.asarray([16, 8, 0], jnp.uint32)
    return ((packed[..., None] >> shifts) & 0xFF).astype(jnp.uint8)


class WarpRenderer:
    """One world's mjx.Data -> (size, size, 3) uint8, on MJX-Warp's ray tracer; call it under jax.vmap over
    exactly `nworld` worlds (Warp sizes its buffers when the context is made)."""

    def __init__(self, model, nworld: int, size: int = IMAGE_SIZE):
        self.size = _check_size(size)
        try:
            import warp  # noqa: F401
            from mujoco import mjx
        except ImportError:
            raise PixelsError("pixels on MJX need MJX-Warp's renderer: pip install 'mjx-pusht[warp]' "
                              "(warp-lang), or use the cpu backend") from None
        self.view = view_model(model, self.size)
        self.target = Target(self.view)
        self.nworld = int(nworld)
        self.mx = mjx.put_model(self.view, impl="warp")
        self.context = mjx.create_render_context(
            self.view, nworld=self.nworld, cam_res=(self.size, self.size), render_rgb=True, render_depth=False,
            use_textures=False, use_shadows=False, cam_active=[CAMERA], enabled_geom_groups=[0],
            enable_specular=False, enable_emission=False, enable_per_light_ambient=False)
        self._ctx = self.context.pytree()
        from mjx_pusht.model import mjx_private

        render_context = mjx_private.render_context()
        self._adr = int(render_context.get(self._ctx).rgb_adr.numpy()[self.view.camera(CAMERA).id])
        # The camera hangs from the world: its pose is a constant (a fresh mjx.Data holds zeros there).
        import mujoco

        host = mujoco.MjData(self.view)
        mujoco.mj_forward(self.view, host)
        self._cam_xpos, self._cam_xmat = host.cam_xpos.copy(), host.cam_xmat.reshape(-1, 3, 3).copy()

    def __call__(self, d, goal=None) -> "jax.Array":  # noqa: F821
        """`goal`: None, the scene's target; else this world's goal (3,) (`Target`)."""
        import jax.numpy as jnp
        from mujoco import mjx

        d = mjx.kinematics(self.mx, d)  # the geoms where qpos puts them (a stepped Data holds the pose before the step)
        if goal is not None:
            xpos, xmat = self.target.at(goal.astype(d.geom_xpos.dtype), jnp)
            d = d.replace(geom_xpos=d.geom_xpos.at[self.target.ids].set(xpos),
                          geom_xmat=d.geom_xmat.at[self.target.ids].set(xmat.reshape(-1, *d.geom_xmat.shape[1:])))
        d = d.replace(cam_xpos=jnp.asarray(self._cam_xpos, d.cam_xpos.dtype),
                      cam_xmat=jnp.asarray(self._cam_xmat, d.cam_xmat.dtype).reshape(d.cam_xmat.shape))
        d = mjx.refit_bvh(self.mx, d, self._ctx)
        rgb, _, _ = mjx.render(self.mx, d, self._ctx)
        n = self.size * self.size
        return unpack_rgb(rgb[..., self._adr : self._adr + n]).reshape(self.size, self.size, 3)
