"""Pixel observations show the scene where the camera model puts it, in the same colours on both renderers."""

from __future__ import annotations

import copy

import mujoco
import numpy as np
import pytest

from mjx_pusht.render.pixels import CAMERA, CpuRenderer, PixelsError, view_model
from mjx_pusht.model.layout import QposLayout
from mjx_pusht.model.scene import SceneSpec, build_model
from mjx_pusht.task.rules import T_RECTS, to_pixels

SIZE = 96


@pytest.fixture(scope="module")
def model():
    return build_model(SceneSpec())


@pytest.fixture(scope="module")
def renderer(model):
    r = CpuRenderer(model, SIZE)
    yield r
    r.close()


def _project(model, points, size):
    """World points -> pixel (column, row) from MuJoCo's own camera pose and an orthographic lens of
    height cam_fovy metres: independent of task.to_pixels."""
    view = view_model(model, size)
    d = mujoco.MjData(view)
    mujoco.mj_forward(view, d)
    cam = view.camera(CAMERA).id
    assert view.cam_projection[cam] == mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC
    pos, axes = d.cam_xpos[cam], d.cam_xmat[cam].reshape(3, 3)  # columns: camera x (right), y (up), z (back)
    half = view.cam_fovy[cam] / 2
    rel = np.c_[points, np.zeros(len(points))] - pos
    u, v = rel @ axes[:, 0], rel @ axes[:, 1]
    return np.c_[(u / half + 1) * size / 2, (1 - v / half) * size / 2]


def _inside_rects(points, pose, margin):
    """Which points lie inside the T at `pose` by more than `margin`, and which outside it by more than `margin`."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dx, dy = points[:, 0] - pose[0], points[:, 1] - pose[1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    inside = np.zeros(len(points), bool)
    outside = np.ones(len(points), bool)
    for cx, cy, hx, hy in T_RECTS:
        inside |= (abs(lx - cx) < hx - margin) & (abs(ly - cy) < hy - margin)
        outside &= (abs(lx - cx) > hx + margin) | (abs(ly - cy) > hy + margin)
    return inside, outside


def _pixel_centres(model, size):
    """The world point at each pixel centre, by inverting the independent projection on a grid."""
    # the projection is affine: solve it from three points
    probe = np.array([[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]])
    px = _project(model, probe, size)
    origin, du, dv = px[0], (px[1] - px[0]) / 0.1, (px[2] - px[0]) / 0.1
    jac = np.c_[du, dv]
    cols, rows = np.meshgrid(np.arange(size) + 0.5, np.arange(size) + 0.5)
    pix = np.c_[cols.ravel(), rows.ravel()]
    return np.linalg.solve(jac, (pix - origin).T).T


def _colour(model, geom, size):
    return np.round(view_model(model, size).geom_rgba[model.geom(geom).id, :3] * 255).astype(int)


def test_the_target_t_is_where_the_camera_model_puts_it(model, renderer):
    layout = QposLayout.of(model)
    # the block and the pusher parked in a far corner, away from the target
    img = renderer(layout.initial_qpos(model, np.array([[0.27, 0.27, 0.0, -0.3, -0.3]])))[0]
    world = _pixel_centres(model, SIZE)
    pixel = 0.78 / SIZE
    inside, outside = _inside_rects(world, (0.0, 0.0, 0.0), margin=0.1 * pixel)
    near_origin = np.hypot(world[:, 0], world[:, 1]) < 0.2  # keep the block and pusher out of the check
    flat = img.reshape(-1, 3).astype(int)
    target, table = _colour(model, "target_bar", SIZE), _colour(model, "table", SIZE)
    assert inside.sum() > 80  # the T covers about 110 pixels at 96 x 96
    assert (abs(flat[inside] - target) <= 1).all()
    assert (abs(flat[outside & near_origin] - table) <= 1).all()
    # and the projection agrees with the documented pixel frame (task.to_pixels) to a hundredth of a pixel
    pts = np.array([[0.06, 0.015], [-0.015, -0.105], [0.3, -0.2]])
    np.testing.assert_allclose(_project(model, pts, SIZE), to_pixels(pts, SIZE), atol=1e-2)


def test_a_random_goals_target_is_drawn_at_that_goal_in_the_envs_pixels(model):
    """`goal="random"` with pixels: each episode's image draws the target T where its goal puts it (the pixels
    inside the goal T, off the block and the pusher, are the target's colour; the rest near it are not), with the
    camera's own projection, not the env's goal arithmetic."""
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.task.goals import goal_poses

    env = PushTEnv(backend="cpu", pixels=SIZE, goal="random")
    seeds = np.arange(6)
    s = env.reset(seeds)
    goals = goal_poses(seeds, "chapter")
    np.testing.assert_array_equal(s.obs["goal"], goals)
    world, pixel = _pixel_centres(model, SIZE), 0.78 / SIZE
    target, table = _colour(model, "target_bar", SIZE), _colour(model, "table", SIZE)
    for i in range(len(seeds)):
        flat = s.obs["pixels"][i].reshape(-1, 3).astype(int)
        tee = s.obs["state"][i, 2:5]
        _, off_block = _inside_rects(world, tee, margin=pixel)
        off_pusher = np.hypot(*(world - s.obs["state"][i, 0:2]).T) > 0.015 + pixel
        shown = off_block & off_pusher
        inside, outside = _inside_rects(world, goals[i], margin=0.1 * pixel)
        assert (inside & shown).sum() > 40, i
        assert (abs(flat[inside & shown] - target) <= 1).all(), i
        near = np.hypot(*(world - goals[i, :2]).T) < 0.2
        assert (abs(flat[outside & near & shown] - table) <= 1).all(), i
        # and nothing is drawn at the scene's own target, the origin, unless this goal covers it
        at_origin, _ = _inside_rects(world, (0.0, 0.0, 0.0), margin=0.1 * pixel)
        assert not (abs(flat[at_origin & outside & shown] - target) <= 1).all(axis=1).any(), i


def test_a_goals_target_is_the_scenes_target_moved_there_by_mujocos_own_kinematics(model):
    """The renderer moves the target's geoms after kinematics; a model whose target body is authored at the goal
    (its pos and quat moved by the goal's rigid motion; mj_kinematics places its geoms) draws the same image."""
    from mjx_pusht.envs.functional import PushTEnv

    for task in ("chapter", "gym-pusht"):
        env = PushTEnv.for_task(task, backend="cpu")
        qpos = env.layout.initial_qpos(env.model, np.array([[0.02, -0.03, 0.4, 0.09, 0.09]]))
        goal = np.array([0.05, -0.04, 2.2])
        moved = copy.deepcopy(env.model)
        body = moved.body("target").id
        assert moved.body_parentid[body] == 0  # hung from the world: body_pos and body_quat are its world pose
        c, s = np.cos(goal[2]), np.sin(goal[2])
        x, y, z = moved.body_pos[body]
        moved.body_pos[body] = (c * x - s * y + goal[0], s * x + c * y + goal[1], z)
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, np.array([np.cos(goal[2] / 2), 0.0, 0.0, np.sin(goal[2] / 2)]), moved.body_quat[body])
        moved.body_quat[body] = quat
        at_goal, authored = CpuRenderer(env.model, SIZE), CpuRenderer(moved, SIZE)
        try:
            a, b, scene = at_goal(qpos, goal), authored(qpos), at_goal(qpos)
        finally:
            at_goal.close(), authored.close()
        assert (a != scene).any(), task  # the target did move
        np.testing.assert_array_equal(a, b)


def test_the_translucent_target_is_drawn_in_the_colour_it_shows_over_the_table(model):
    authored = model.geom_rgba[model.geom("target_bar").id]
    table = model.geom_rgba[model.geom("table").id, :3]
    assert authored[3] == 0.5  # the chapter's translucent green T
    blended = np.round((authored[3] * authored[:3] + (1 - authored[3]) * table) * 255)
    np.testing.assert_array_equal(_colour(model, "target_bar", SIZE), blended)
    assert model.cam_projection[model.camera(CAMERA).id] == mujoco.mjtProjection.mjPROJ_PERSPECTIVE  # untouched


def test_a_rotated_block_covers_exactly_its_own_pixels(model, renderer):
    layout = QposLayout.of(model)
    pose = (0.12, -0.08, 0.7)
    img = renderer(layout.initial_qpos(model, np.array([[*pose, -0.3, 0.3]])))[0]
    world = _pixel_centres(model, SIZE)
    inside, outside = _inside_rects(world, pose, margin=0.1 * 0.78 / SIZE)
    flat = img.reshape(-1, 3).astype(int)
    tee = _colour(model, "tee_bar", SIZE)
    assert inside.sum() > 80
    assert (abs(flat[inside] - tee) <= 1).all()
    assert not (abs(flat[outside] - tee) <= 1).all(axis=1).any()


def test_a_renderer_makes_no_shadow_map_that_nothing_draws_into(model, monkeypatch):
    """No light in either scene casts a shadow, so a renderer asks MuJoCo for no shadow map: its pixels are those of
    a render context with MuJoCo's default 4096 x 4096 map, and it costs a third of the memory. (LeRobot's vector of
    500 drop-in envs, one context each, was killed past 24 GB with the map.) The gym-pusht scene's renderer is the
    drop-in's, the one LeRobot makes 500 of; the chapter's shares view_model."""
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.render import pixels

    assert not model.light_castshadow.any() and view_model(model, SIZE).vis.quality.shadowsize == 0
    model = PushTEnv.for_task("gym-pusht", backend="cpu").model
    assert not model.light_castshadow.any() and view_model(model, SIZE).vis.quality.shadowsize == 0
    rng = np.random.default_rng(0)
    q = model.qpos0 + rng.uniform(-0.05, 0.05, (16, model.nq))

    def rss_mb():
        return int(open("/proc/self/status").read().split("VmRSS:")[1].split()[0]) / 1024

    def renderers(n):
        before, made = rss_mb(), [CpuRenderer(model, SIZE) for _ in range(n)]
        images = [r(q) for r in made][-1]
        cost = (rss_mb() - before) / n
        for r in made:
            r.close()
        return images, cost

    renderers(1)  # EGL's one-time set-up out of the way
    ours, ours_mb = renderers(3)
    shadowed = view_model

    def with_default_map(m, size=SIZE):
        view = shadowed(m, size)
        view.vis.quality.shadowsize = mujoco.MjModel.from_xml_string("<mujoco/>").vis.quality.shadowsize
        return view

    monkeypatch.setattr(pixels, "view_model", with_default_map)
    theirs, theirs_mb = renderers(3)
    np.testing.assert_array_equal(ours, theirs)
    assert ours.std() > 10  # a scene, not a blank frame
    assert ours_mb < theirs_mb / 2, (ours_mb, theirs_mb)


def test_bad_sizes_and_missing_gl_are_one_line(model, monkeypatch):
    with pytest.raises(ValueError, match="image size"):
        CpuRenderer(model, 3)

    def broken(*a, **k):
        raise RuntimeError("eglInitialize failed\nmore")

    monkeypatch.setattr(mujoco, "GLContext", broken)
    with pytest.raises(PixelsError, match="apt-get install") as e:
        CpuRenderer(model, SIZE)
    assert "\n" not in str(e.value)


def test_a_script_that_renders_on_the_cpu_exits_without_a_traceback():
    """MuJoCo tears the EGL display down in an exit hook; a renderer still open then was closed after it and
    printed EGL_NOT_INITIALIZED tracebacks at every such exit, whenever anything had made a weakref finalizer
    before the first GL context (as this script does first). Now the renderer closes first."""
    import subprocess
    import sys

    from helpers import ENV

    script = """
import weakref
class Early: pass
early = Early(); weakref.finalize(early, print, end="")  # weakref's exit hook, before any GL context's
import numpy as np
from mjx_pusht.envs.functional import PushTEnv
env = PushTEnv(backend="cpu", pixels=96, reset_kind="task")  # alive at exit, as a script's env is
print(env.reset(np.arange(2)).obs["pixels"].shape)
"""
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=ENV, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "(2, 96, 96, 3)", r.stderr
    assert "Traceback" not in r.stderr and "EGL" not in r.stderr, r.stderr


@pytest.mark.slow
@pytest.mark.warp
@pytest.mark.parametrize("goal", ["fixed", "random"])
def test_mjx_warp_renders_the_cpus_image_of_the_same_states(goal):
    """MJX-Warp's ray tracer (through Warp's CPU device here) against MuJoCo C's OpenGL, same states (with random
    goals, the target drawn at each world's goal)."""
    from mjx_pusht.backends.warp import warp_available
    from mjx_pusht.envs.functional import PushTEnv

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    seeds = np.arange(4)
    cpu, warp = PushTEnv(backend="cpu", pixels=SIZE, goal=goal), PushTEnv(backend="mjx-warp", pixels=SIZE, goal=goal)
    a, b = cpu.reset(seeds), warp.reset(seeds)
    act = np.tile([[0.3, 0.4]], (len(seeds), 1))
    for _ in range(3):
        a, b = cpu.step(a, act), warp.step(b, act)
    pa, pb = a.obs["pixels"], np.asarray(b.obs["pixels"])
    assert pb.dtype == np.uint8 and pb.shape == pa.shape == (4, SIZE, SIZE, 3)
    differ = (pa != pb).any(axis=-1)
    # the same colours (exact bytes) and the same geometry, but for a pixel whose centre falls on an edge
    assert differ.mean() < 1e-3, differ.sum()
    for i in range(len(seeds)):
        colours_a, counts_a = np.unique(pa[i].reshape(-1, 3), axis=0, return_counts=True)
        colours_b, counts_b = np.unique(pb[i].reshape(-1, 3), axis=0, return_counts=True)
        np.testing.assert_array_equal(colours_a[counts_a > 4], colours_b[counts_b > 4])


def test_eval_video_draws_each_episode_in_its_tile(tmp_path):
    from PIL import Image

    from mjx_pusht.cli.commands import main

    gif = tmp_path / "expert.gif"
    assert main(["eval", "--seeds", "4", "--backend", "cpu", "--reset", "chapter", "--max-steps", "12",
                 "--no-rerun", "--no-progress", "--out", str(tmp_path / "ev"), "--video", str(gif),
                 "--video-size", "64"]) == 0
    im = Image.open(gif)
    assert im.size == (128, 128)  # 4 episodes: a 2 x 2 grid of 64-pixel tiles
    assert im.info["duration"] == 100  # 10 control steps a second: real time
    im.seek(0)
    first = np.asarray(im.convert("RGB")).astype(int)
    tee = _colour(build_model(SceneSpec()), "tee_bar", 64)
    for r in range(2):
        for c in range(2):
            tile = first[r * 64 + 12:(r + 1) * 64 - 1, c * 64:(c + 1) * 64 - 1]  # below the label
            assert (abs(tile - tee) <= 2).all(axis=-1).sum() >= 5, (r, c)  # every tile shows its block


def test_a_tiles_label_shows_whole_even_a_held_out_seeds():
    """Every character of `seed N  coverage C` shows on its tile, at the default 128 px and at 64: the last digit of
    the coverage changes the tile, and no ink reaches the tile's right edge (once, at 128 px a held-out seed's
    label was cut to `seed 1000000000 cover`)."""
    from mjx_pusht.io.video import _label

    for size in (128, 64):
        tile = np.full((size, size, 3), 255, np.uint8)
        for seed in (7, 1_000_000_000):
            a, b = (_label(tile, f"seed {seed}  coverage 0.9{d}", False) for d in (5, 6))
            assert (a != b).any(), (size, seed)
            ink = a.astype(int).sum(-1) < 500  # the dark text on the white band
            assert ink.any() and not ink[:, -3:].any(), (size, seed)


def test_bad_video_requests_fail_in_one_line_before_any_episode(tmp_path, capsys):
    from mjx_pusht.cli.commands import main

    assert main(["eval", "--seeds", "4", "--out", str(tmp_path / "ev"), "--video", str(tmp_path / "v.avi")]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ".gif or .mp4" in err
    assert not (tmp_path / "ev").exists()
    assert main(["eval", "--seeds", "4", "--out", str(tmp_path / "ev"), "--video", str(tmp_path / "no" / "v.gif")]) == 1
    assert "does not exist" in capsys.readouterr().err


# reading the file back starts ffmpeg too (a fork that execs at once), which JAX warns about
@pytest.mark.filterwarnings(r"ignore:os\.fork\(\) was called:RuntimeWarning")
def test_mp4_holds_the_frames_it_was_given(tmp_path):
    iio = pytest.importorskip("imageio.v3")
    pytest.importorskip("imageio_ffmpeg")
    from mjx_pusht.io.video import write

    frames = np.zeros((12, 64, 96, 3), np.uint8)
    frames[:, :, :48] = (200, 40, 40)  # left half red, right half black: survives the codec's rounding
    write(tmp_path / "v.mp4", frames, fps=10)
    back = iio.imread(tmp_path / "v.mp4")
    assert back.shape == (12, 64, 96, 3)
    assert abs(back[:, :, :40].mean(axis=(0, 1, 2)) - [200, 40, 40]).max() < 12
    assert back[:, :, 56:].mean() < 12
    assert not list(tmp_path.glob("*.partial*"))  # written to a temporary name, then moved into place
