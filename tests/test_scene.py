"""The chapter's scene, its numbers, and the tree check that keeps it the authored scene."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.model.scene import SceneSpec, build_model, compile_xml, scene_xml
from mjx_pusht.model.tree import TreeMismatch, check_tree, read_tree
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.reset import start_pose


def chapter_loop(break_it: str, seed: int, nudge_steps: int = 120):
    """The chapter's script, step for step: its own mj_step loop reading geom_xpos, independent of the backends."""
    model = mujoco.MjModel.from_xml_string(scene_xml(SceneSpec(break_it)))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(seed)
    adr = [int(model.joint(n).qposadr[0]) for n in ("tee_x", "tee_y", "tee_yaw")]
    data.qpos[adr[0]] = float(rng.uniform(-0.03, 0.03))
    data.qpos[adr[1]] = float(rng.uniform(0.02, 0.06))
    data.qpos[adr[2]] = float(rng.uniform(-0.2, 0.2))
    data.qpos[int(model.joint("pusher_y").qposadr[0])] = -0.25
    mujoco.mj_forward(model, data)
    bar, stem = model.geom("tee_bar").id, model.geom("tee_stem").id

    def gap():
        return float(np.linalg.norm(data.geom_xpos[bar] - data.geom_xpos[stem]))

    peak = abs(gap() - 0.06)
    for _ in range(40):
        data.ctrl[:] = 0.0
        mujoco.mj_step(model, data)
        peak = max(peak, abs(gap() - 0.06))
    settled, gap_settled = data.qpos[adr].copy(), gap()
    for _ in range(nudge_steps):
        data.ctrl[0], data.ctrl[1] = 0.0, 1.0
        mujoco.mj_step(model, data)
        peak = max(peak, abs(gap() - 0.06))
    return {"settled": settled, "final": data.qpos[adr].copy(), "gap_settled": gap_settled, "peak": peak}


def test_welded_tree_is_three_bodies_five_joints():
    tree = check_tree(build_model(SceneSpec()), "none")
    assert tree.n_bodies == 3 and tree.n_joints == 5 and tree.nq == tree.nv == 5 and tree.nu == 2
    assert tree.joint_types == ["slide", "slide", "hinge", "slide", "slide"]
    assert [p for _, p in tree.bodies] == ["world"] * 3


def test_split_tree_is_four_bodies_eight_joints():
    tree = check_tree(build_model(SceneSpec("split-tee")), "split-tee")
    assert tree.n_bodies == 4 and tree.n_joints == 8 and tree.nq == tree.nv == 8


def test_welded_seed0_reproduces_the_chapter(cpu_runs):
    r = cpu_runs[("none", "cylinder")]
    assert r.settled[0, 1] == pytest.approx(0.031, abs=5e-4)  # chapter: y ~= 0.031
    assert r.final[0, 1] == pytest.approx(0.376, abs=1e-3)  # chapter: y ~= 0.376
    assert round(r.gap_max_dev[0], 6) == 0.0 and r.gap_settled[0] == pytest.approx(0.06, abs=1e-12)
    assert r.rigid[0]


def test_split_tee_settles_apart(cpu_runs):
    r = cpu_runs[("split-tee", "cylinder")]
    assert r.gap_settled[0] == pytest.approx(0.0912, abs=5e-4)  # chapter: 0.0912 m at rest
    assert r.gap_max_dev[0] >= 0.03
    assert not r.rigid.any()


@pytest.mark.parametrize("break_it", ["none", "split-tee"])
def test_cpu_backend_is_the_chapter_loop_to_the_bit(cpu_runs, break_it):
    r = cpu_runs[(break_it, "cylinder")]
    for s in range(4):
        ref = chapter_loop(break_it, s)
        np.testing.assert_array_equal(r.settled[s], ref["settled"])
        np.testing.assert_array_equal(r.final[s], ref["final"])
        # the same geom positions (qpos above is equal to the bit); the chapter's np.linalg.norm of one
        # 3-vector is a dot product, ours a batched sum of squares, and NumPy builds differ in the last bit
        np.testing.assert_array_max_ulp(r.gap_settled[s], ref["gap_settled"], maxulp=2)
        assert r.gap_max_dev[s] == pytest.approx(ref["peak"], abs=1e-15)


def test_reset_draws_x_then_y_then_yaw_from_one_generator():
    rng = np.random.default_rng(7)
    expect = (rng.uniform(-0.03, 0.03), rng.uniform(0.02, 0.06), rng.uniform(-0.2, 0.2))
    assert start_pose(7) == expect


def test_welded_T_gap_is_point_zero_six_every_step_on_every_seed(cpu_runs):
    assert np.all(cpu_runs[("none", "cylinder")].gap_max_dev < 1e-12)


def test_tree_check_catches_an_added_joint():
    xml = scene_xml(SceneSpec()).replace(
        '<joint name="pusher_y"', '<joint name="pusher_z" type="slide" axis="0 0 1"/>\n      <joint name="pusher_y"'
    )
    with pytest.raises(TreeMismatch) as e:
        check_tree(compile_xml(xml), "none")
    msg = str(e.value)
    assert "nq is 6, expected 5" in msg and "pusher_z:slide" in msg


def test_tree_check_catches_a_split_tee_passed_off_as_welded():
    model = compile_xml(scene_xml(SceneSpec("split-tee")))
    with pytest.raises(TreeMismatch) as e:
        check_tree(model, "none")
    assert "n_bodies is 4, expected 3" in str(e.value) and "tee_stem_body<-world" in str(e.value)


def test_read_tree_reads_the_compiled_model_not_the_xml():
    xml = scene_xml(SceneSpec()).replace('type="hinge" axis="0 0 1" damping="0.02"', 'type="slide" axis="0 0 1" damping="0.02"')
    tree = read_tree(compile_xml(xml))
    assert tree.joint_types == ["slide", "slide", "slide", "slide", "slide"]


def test_free_tee_grants_six_dofs_and_leaves_the_plane():
    model = build_model(SceneSpec("free-tee"))
    assert read_tree(model).nq == 9 and read_tree(model).nv == 8
    r = run_cpu(Scenario(SceneSpec("free-tee")), np.arange(2), trace=True)
    z = r.trace.qpos[:, -1, 2]
    t = 160 * 0.01  # free fall from z=0.0152 for the whole run: nothing holds it on a collision-free table
    np.testing.assert_allclose(z, 0.0152 - 0.5 * 9.81 * t**2, rtol=0.02)
