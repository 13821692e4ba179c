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

`CpuRenderer` renders (N, nq) positions with `mujoco.Renderer` (headless through EGL or
OSMesa: `MUJOCO_GL`); `WarpRenderer` renders one world's `mjx.Data` inside a vmapped, jitted
program (MJX-Warp's batched ray tracer), so images never leave the device per step.
"""

from __future__ import annotations

import copy
import os

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
    view.vis.global_.offwidth = max(int(view.vis.global_.offwidth), size)
    view.vis.global_.offheight = max(int(view.vis.global_.offheight), size)
    return view


def _check_size(size: int) -> int:
    if int(size) != size or not 8 <= size <= 2048:
        raise ConfigError(f"image size must be an integer from 8 to 2048 pixels, got {size}")
    return int(size)


class CpuRenderer:
    """(N, nq) positions -> (N, size, size, 3) uint8 images, through MuJoCo C's OpenGL renderer."""

    def __init__(self, model, size: int = IMAGE_SIZE):
        import mujoco

        self.size = _check_size(size)
        missing = os.environ.get("MJX_PUSHT_GL_MISSING")
        if missing:  # set aside at import (mjx_pusht/__init__.py): its library is not installed
            lib = {"egl": "EGL (apt-get install libegl1 libgl1-mesa-dri)",
                   "osmesa": "OSMesa (apt-get install libosmesa6)"}[missing]
            raise PixelsError(f"MUJOCO_GL={missing} but {lib} is not installed: install it, or set MUJOCO_GL "
                              "to a GL this machine has (pixels only; everything else runs without GL)")
        self.view = view_model(model, self.size)
        self.data = mujoco.MjData(self.view)
        try:
            self.renderer = mujoco.Renderer(self.view, self.size, self.size)
        except Exception as e:  # GL missing or unusable: say what to install, not a traceback
            gl = os.environ.get("MUJOCO_GL", "") or "glfw"
            raise PixelsError(
                f"the CPU renderer needs OpenGL without a screen (MUJOCO_GL={gl} failed: {str(e).splitlines()[0]}); "
                "install EGL (Debian: apt-get install libegl1 libgl1-mesa-dri) and set MUJOCO_GL=egl, "
                "or OSMesa (apt-get install libosmesa6) and MUJOCO_GL=osmesa") from None
        self._camera = self.view.camera(CAMERA).id
        import atexit
        import weakref

        # Closed when this renderer goes, or at exit before EGL is torn down (else its destructor complains). MuJoCo
        # terminates the EGL display in an exit hook it registers with the first GL context; weakref's own exit hook
        # may have been registered before that, and exit hooks run last-registered first, so a finalizer left to it
        # ran after the display was gone (EGL_NOT_INITIALIZED tracebacks at exit). Registered here, after the
        # context, it runs before. (Once it has run, it holds nothing.)
        close = weakref.finalize(self, self.renderer.close)
        close.atexit = False
        atexit.register(close)

    def __call__(self, qpos) -> np.ndarray:
        import mujoco

        qpos = np.atleast_2d(np.asarray(qpos, np.float64))
        out = np.empty((len(qpos), self.size, self.size, 3), np.uint8)
        for i, q in enumerate(qpos):
            self.data.qpos[:] = q
            mujoco.mj_kinematics(self.view, self.data)
            mujoco.mj_camlight(self.view, self.data)
            self.renderer.update_scene(self.data, camera=self._camera)
            out[i] = self.renderer.render()
        return out

    def close(self) -> None:
        self.renderer.close()


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
        self.nworld = int(nworld)
        self.mx = mjx.put_model(self.view, impl="warp")
        self.context = mjx.create_render_context(
            self.view, nworld=self.nworld, cam_res=(self.size, self.size), render_rgb=True, render_depth=False,
            use_textures=False, use_shadows=False, cam_active=[CAMERA], enabled_geom_groups=[0],
            enable_specular=False, enable_emission=False, enable_per_light_ambient=False)
        self._ctx = self.context.pytree()
        from mujoco.mjx.warp import render_context

        self._adr = int(render_context.get(self._ctx).rgb_adr.numpy()[self.view.camera(CAMERA).id])
        # The camera hangs from the world: its pose is a constant (a fresh mjx.Data holds zeros there).
        import mujoco

        host = mujoco.MjData(self.view)
        mujoco.mj_forward(self.view, host)
        self._cam_xpos, self._cam_xmat = host.cam_xpos.copy(), host.cam_xmat.reshape(-1, 3, 3).copy()

    def __call__(self, d) -> "jax.Array":  # noqa: F821
        import jax.numpy as jnp
        from mujoco import mjx

        d = mjx.kinematics(self.mx, d)  # the geoms where qpos puts them (a stepped Data holds the pose before the step)
        d = d.replace(cam_xpos=jnp.asarray(self._cam_xpos, d.cam_xpos.dtype),
                      cam_xmat=jnp.asarray(self._cam_xmat, d.cam_xmat.dtype).reshape(d.cam_xmat.shape))
        d = mjx.refit_bvh(self.mx, d, self._ctx)
        rgb, _, _ = mjx.render(self.mx, d, self._ctx)
        n = self.size * self.size
        return unpack_rgb(rgb[..., self._adr : self._adr + n]).reshape(self.size, self.size, 3)
