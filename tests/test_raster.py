"""The raster renderer (render/raster.py, plain JAX ops) draws the image MuJoCo C's OpenGL and MJX-Warp's ray tracer
draw of the same states, on both scenes, at any goal, and runs sharded over devices where MJX-Warp cannot."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys

import jax
import mujoco
import numpy as np
import pytest

from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.model.scene import SceneSpec, build_model
from mjx_pusht.render.pixels import CAMERA, CpuRenderer, PixelsError, view_model
from mjx_pusht.render.raster import Raster

TASKS = ("chapter", "gym-pusht")
N = 24  # states a case: 8 anywhere, 8 with the pusher touching the T, 8 with it on the frame's edge


def _states(env, seed: int):
    """(N, 5) states and (N, 3) goals inside the camera's frame (MuJoCo's own camera pose and extent): the T anywhere
    inside the walls at any yaw; the pusher anywhere (over the T too: the renderers draw what is highest), touching
    the T's bar, or on the frame's edge (gym-pusht's walls, which sit on its table's edge); goals anywhere."""
    view = view_model(env.model)
    d = mujoco.MjData(view)
    mujoco.mj_forward(view, d)
    cam = view.camera(CAMERA).id
    centre, axes, half = d.cam_xpos[cam, :2], d.cam_xmat[cam].reshape(3, 3)[:2, :2], view.cam_fovy[cam] / 2
    rng = np.random.default_rng(seed)

    def world(uv):
        return centre + uv @ axes.T

    states = np.c_[world(rng.uniform(-half, half, (N, 2))), world(rng.uniform(-half + 0.03, half - 0.03, (N, 2))),
                   rng.uniform(-np.pi, np.pi, N)]
    edge = rng.uniform(-half, half, (8, 2))
    edge[np.arange(8), np.arange(8) % 2] = np.tile([half - 0.004, -half + 0.004, half + 0.004, -half - 0.004], 2)
    states[16:, :2] = world(edge)
    # touching: the pusher's disk against the bar's long side, where MuJoCo's kinematics puts the bar
    bar, radius = view.geom("tee_bar").id, view.geom_size[view.geom("pusher_tip").id, 0]
    for i in range(8, 16):
        d.qpos[:] = env.layout.qpos_of_state(np.asarray(view.qpos0), states[i])
        mujoco.mj_kinematics(view, d)
        rot, along = d.geom_xmat[bar].reshape(3, 3)[:2, :2], rng.uniform(-1, 1) * view.geom_size[bar, 0]
        states[i, :2] = d.geom_xpos[bar, :2] + rot @ (along, rng.choice([-1, 1]) * (view.geom_size[bar, 1] + radius))
    goals = np.c_[world(rng.uniform(-half + 0.05, half - 0.05, (N, 2))), rng.uniform(-np.pi, np.pi, N)]
    return states.astype(np.float32), goals.astype(np.float32)


def _mujoco_poses(raster, qpos):
    """Every geom's world pose at each qpos by MuJoCo C's kinematics (not MJX's), as float32 a device holds."""
    d = mujoco.MjData(raster.view)
    xpos, xmat = [], []
    for q in qpos:
        d.qpos[:] = q
        mujoco.mj_kinematics(raster.view, d)
        xpos.append(d.geom_xpos.copy()), xmat.append(d.geom_xmat.copy())
    return np.float32(xpos), np.float32(xmat)


def assert_same_picture(ours, theirs):
    """test_pixels.py's bound for MJX-Warp against MuJoCo C: the same colours (exact bytes) in every image, and under
    1e-3 of the pixels differing; here also each differing pixel is an edge: one image's colour there shows next to
    it in the other."""
    assert ours.dtype == theirs.dtype == np.uint8 and ours.shape == theirs.shape
    differ = (ours != theirs).any(axis=-1)
    assert differ.mean() < 1e-3, differ.sum()
    pad = ((0, 0), (1, 1), (1, 1), (0, 0))
    padded_ours, padded_theirs = np.pad(ours, pad, mode="edge"), np.pad(theirs, pad, mode="edge")
    for i, r, c in zip(*np.nonzero(differ)):  # (a sliver, gym-pusht's 2 mm outline, may show in one image only)
        assert ((padded_theirs[i, r:r + 3, c:c + 3] == ours[i, r, c]).all(axis=-1).any()
                or (padded_ours[i, r:r + 3, c:c + 3] == theirs[i, r, c]).all(axis=-1).any()), (i, r, c)
    for a, b in zip(ours, theirs):
        colours_a, counts_a = np.unique(a.reshape(-1, 3), axis=0, return_counts=True)
        colours_b, counts_b = np.unique(b.reshape(-1, 3), axis=0, return_counts=True)
        np.testing.assert_array_equal(colours_a[counts_a > 4], colours_b[counts_b > 4])


def _against_mujoco(model, layout, states, goals, size):
    """The raster's images (from MuJoCo C's geom poses) and MuJoCo C's OpenGL images of the same states."""
    raster = Raster(model, size)
    qpos = layout.qpos_of_state(np.asarray(model.qpos0), states.astype(np.float64))
    xpos, xmat = _mujoco_poses(raster, qpos)
    ours = np.asarray(jax.jit(jax.vmap(raster.draw))(xpos, xmat, goals))
    cpu = CpuRenderer(model, size)
    try:
        return ours, cpu(qpos, goals)
    finally:
        cpu.close()


@pytest.mark.parametrize("task", TASKS)
@pytest.mark.parametrize("size", [96, 64])
@pytest.mark.parametrize("goal", ["fixed", "random"])
def test_the_raster_draws_mujoco_cs_opengl_image_of_the_same_states(task, size, goal):
    env = PushTEnv.for_task(task)
    states, goals = _states(env, seed=size)
    ours, theirs = _against_mujoco(env.model, env.layout, states, goals if goal == "random" else None, size)
    assert_same_picture(ours, theirs)
    colours = np.unique(theirs.reshape(-1, 3), axis=0)
    assert len(colours) >= (4 if task == "chapter" else 6)  # table, target, T, pusher (+ floor, outlines)


@pytest.mark.parametrize("case", ["capsule pusher", "sphere shown", "small table", "infinite table"])
def test_capsules_spheres_and_planes_as_mujoco_draws_them(case):
    """The shapes the scenes above do not show: the capsule pusher (the chapter's other pusher), gym-pusht's sphere
    tip put in group 0 (a curved top, over and under the cylinders' flat ones), a table plane smaller than the
    frame (outside every geom MuJoCo shows black, and so does the raster) and one of size 0 (infinite)."""
    model = build_model(SceneSpec(pusher="capsule") if case == "capsule pusher" else
                        SceneSpec(variant="gym-pusht") if case == "sphere shown" else SceneSpec())
    if case == "sphere shown":
        tip = model.geom("pusher_tip").id
        model.geom_group[tip], model.geom_rgba[tip] = 0, (0.9, 0.1, 0.1, 1)  # its own colour: its curve shows
    if case.endswith("table"):
        model.geom_size[model.geom("table").id, :2] = 0.25 if case == "small table" else 0
    env = PushTEnv.for_task("gym-pusht" if case == "sphere shown" else "chapter")
    states, goals = _states(env, seed=7)
    ours, theirs = _against_mujoco(model, env.layout, states, goals, 64)
    assert_same_picture(ours, theirs)
    black = (theirs == 0).all(axis=-1).mean()
    assert black > 0.3 if case == "small table" else black == 0


@pytest.mark.slow
@pytest.mark.warp
def test_the_raster_draws_mjx_warps_image_of_the_same_data():
    """Through the same one-world mjx.Data each (MJX's kinematics in the raster, under vmap and jit), on Warp's CPU
    device: both scenes, two sizes, with the scene's target and with random goals."""
    import jax.numpy as jnp

    from mjx_pusht.render.pixels import WarpRenderer

    for task in TASKS:
        env = PushTEnv.for_task(task, backend="mjx-warp")
        states, goals = _states(env, seed=3)
        qpos = jnp.asarray(env.layout.qpos_of_state(np.asarray(env.model.qpos0), states))
        d0 = env.template(N)
        for size in (96, 64):
            raster, warp = Raster(env.model, size), WarpRenderer(env.model, N, size)
            for g in (None, jnp.asarray(goals)):
                ours, theirs = (np.asarray(jax.jit(jax.vmap(lambda q, gg, r=r: r(d0.replace(qpos=q), gg)))(qpos, g))
                                for r in (raster, warp))
                assert_same_picture(ours, theirs)


SHARDED = """
import json, sys
import jax, numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.backends.jax_setup import enable_compilation_cache
from mjx_pusht.render.raster import state_images

enable_compilation_cache()  # a second run compiles nothing

states, goals = (np.asarray(a, np.float32) for a in json.loads(sys.stdin.read()))
images = state_images(PushTEnv.for_task("gym-pusht", pixels=64))
mesh = Mesh(np.array(jax.devices()[:2]), ("d",))
sharded = jax.jit(jax.shard_map(images, mesh=mesh, in_specs=(P("d"), P("d")), out_specs=P("d")))
put = NamedSharding(mesh, P("d"))
a = sharded(jax.device_put(states, put), jax.device_put(goals, put))
b = jax.jit(images)(states, goals)
print(json.dumps({"devices": len(a.sharding.device_set), "equal": bool((np.asarray(a) == np.asarray(b)).all()),
                  "image": np.asarray(a)[3].tolist()}))
"""


@pytest.mark.slow  # a subprocess of its own: imports JAX and MJX and compiles twice (9-14 s on 2 cores)
def test_it_runs_under_shard_map_over_two_devices_with_the_same_images():
    """In a process with 2 forced CPU devices (JAX fixes its device count at import): state_images shard_map'd over
    both, each device drawing its half of the batch, gives the one-device program's images to the bit."""
    env = PushTEnv.for_task("gym-pusht")
    states, goals = _states(env, seed=11)
    r = subprocess.run([sys.executable, "-c", SHARDED], input=json.dumps([states[:8].tolist(), goals[:8].tolist()]),
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2",
                            "JAX_PLATFORMS": "cpu"})
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["devices"] == 2 and out["equal"]
    # and those images are the scene's: row 3 against MuJoCo C's OpenGL
    ours, theirs = _against_mujoco(env.model, env.layout, states[3:4], goals[3:4], 64)
    assert_same_picture(np.asarray(out["image"], np.uint8)[None], theirs)


def test_a_model_it_would_draw_wrongly_is_refused_in_one_line():
    base = build_model(SceneSpec())
    tilted = copy.deepcopy(base)
    bar = tilted.geom("tee_bar").id
    tilted.geom_quat[bar], tilted.geom_sameframe[bar] = (np.cos(0.1), np.sin(0.1), 0, 0), 0  # tipped about x
    camera = copy.deepcopy(base)
    camera.cam_quat[camera.camera(CAMERA).id] = (np.cos(0.1), 0, np.sin(0.1), 0)  # looking a little sideways
    hinge = copy.deepcopy(base)
    hinge.jnt_axis[hinge.joint("tee_yaw").id] = (0, 1, 0)  # the T turns about y
    ellipsoid = copy.deepcopy(base)
    ellipsoid.geom_type[ellipsoid.geom("pusher_tip").id] = mujoco.mjtGeom.mjGEOM_ELLIPSOID
    translucent = copy.deepcopy(base)
    translucent.geom_rgba[translucent.geom("tee_bar").id, 3] = 0.5
    for model, needle in [(tilted, "geom tee_bar is tilted"), (ellipsoid, "geom pusher_tip is of type ellipsoid"),
                          (translucent, "geom tee_bar has alpha 0.5"),
                          (hinge, "geom tee_bar can turn about another axis \\(joint tee_yaw\\)"),
                          (build_model(SceneSpec("free-tee")), "joint tee_free"),
                          (camera, "an orthographic camera looking straight down")]:
        with pytest.raises(PixelsError, match=needle) as e:
            Raster(model, 64)
        assert "\n" not in str(e.value)
