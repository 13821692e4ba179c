"""The drop-in's block moves as gym-pusht's moves: gym-pusht 0.1.8 (pymunk) itself, side by side, the same pushes.

gym-pusht's space keeps no velocity between steps (damping 0), has frictionless contacts, a kinematic
agent and a T of mass 1 and moment 3000 px^2 turning about its centre of gravity; the drop-in's
`gym-pusht` scene is that space in MuJoCo (model/gym_pusht_scene.py). Every test below starts both
from the same reset_to_state and sends both the same pixel targets; the tolerances are the measured
agreement with a margin (docs/dropin-physics.md), far inside the 9-27 px the chapter's physics left.
"""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import mjx_pusht  # noqa: F401  (registers the env ids)
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.model.layout import QposLayout
from mjx_pusht.model.scene import SceneSpec, build_model

gym_pusht = pytest.importorskip("gym_pusht")  # a test extra: pip install 'mjx-pusht[test]'
OURS, THEIRS = "mjx_pusht/PushT-gym-pusht-v0", "gym_pusht/PushT-v0"
HOLD = 15  # control steps each push ends with its last target held, so both settle

# (reset_to_state [agent x, y, block x, y, angle], the push): pixel targets, one per control step
STARTS = [
    [256.0, 430.0, 256.0, 300.0, 0.0],  # the agent under the stem
    [100.0, 120.0, 300.0, 250.0, 1.2],
    [420.0, 300.0, 200.0, 220.0, -2.3],
    [250.0, 250.0, 170.0, 360.0, 2.9],  # near the south-west walls
    [480.0, 60.0, 380.0, 150.0, -0.7],  # near the north-east walls
]


def _pushes(start):
    """Three fixed pushes from a start: at the block's origin, along a line through the block and on past
    it, and a slow circle that sweeps across the T. None pins the T against a wall (docs/dropin-physics.md:
    gym-pusht's agent then pushes it through the wall)."""
    block = np.array(start[2:4])
    through = np.linspace(start[0:2], block + 0.8 * (block - np.array(start[0:2])), 40).clip(10, 502)
    t = np.linspace(0, 2 * np.pi, 40)
    circle = block + 60 * np.stack([np.cos(t), np.sin(t)], -1)
    pushes = {"at_origin": np.repeat(block[None], 30, 0), "through": through, "circle": circle.clip(10, 502)}
    return {k: np.concatenate([v, np.repeat(v[-1:], HOLD, 0)]) for k, v in pushes.items()}  # then hold still


def _run(env_id, start, targets):
    env = gym.make(env_id, obs_type="state")
    obs, _ = env.reset(options={"reset_to_state": start})
    out = [obs]
    for a in targets:
        obs, *_ = env.step(np.asarray(a, np.float64))
        out.append(obs)
    env.close()
    return np.array(out, np.float64)


def _apart(theirs, ours):
    """Per step: agent and block origin apart (px), block angles apart (degrees)."""
    agent = np.hypot(*(ours[:, 0:2] - theirs[:, 0:2]).T)
    block = np.hypot(*(ours[:, 2:4] - theirs[:, 2:4]).T)
    angle = np.degrees(np.abs((ours[:, 4] - theirs[:, 4] + np.pi) % (2 * np.pi) - np.pi))
    return agent, block, angle


@pytest.fixture(scope="module")
def side_by_side():
    rows = []
    for start in STARTS:
        for name, targets in _pushes(start).items():
            theirs, ours = _run(THEIRS, start, targets), _run(OURS, start, targets)
            rows.append((start, name, theirs, ours))
    return rows


def test_the_same_pushes_leave_the_block_where_gym_pusht_leaves_it(side_by_side):
    moved, final = 0, []
    for start, name, theirs, ours in side_by_side:
        agent, block, angle = _apart(theirs, ours)
        assert agent.max() < 1e-3, (start, name)  # the agent: gym-pusht's PD law, nothing slows it
        # on the way: pymunk moves its block with the velocity its previous step solved for, so in a fast
        # push it trails by up to one step of the agent's travel (measured: 3.4 px, 2.4 degrees at most)
        assert block.max() < 5.0 and angle.max() < 3.5, (start, name, block.max(), angle.max())
        assert block[-1] < 5.0 and angle[-1] < 2.0, (start, name, block[-1], angle[-1])
        final.append((block[-1], angle[-1]))
        moved += np.hypot(*(theirs[-1, 2:4] - theirs[0, 2:4])) > 20
    assert moved >= 12  # the pushes do push: most move the block tens to hundreds of pixels
    # settled, where the pushes leave it (measured: median 0.06 px, 0.06 degrees over the 15 pushes)
    assert np.median([b for b, _ in final]) < 0.3 and np.median([a for _, a in final]) < 0.3


def test_a_block_left_alone_stops_at_once_as_gym_pushts_does(side_by_side):
    # the agent walks off; gym-pusht keeps no velocity between steps, so neither block drifts
    start = STARTS[0]
    block = np.array(start[2:4])
    push = np.linspace(start[0:2], block + [0, -40], 12)
    away = np.repeat([[40.0, 470.0]], 15, 0)
    theirs, ours = _run(THEIRS, start, np.concatenate([push, away])), _run(OURS, start, np.concatenate([push, away]))
    assert np.hypot(*(theirs[12, 2:4] - theirs[0, 2:4])) > 5  # it was pushed
    for side in (theirs, ours):
        assert np.abs(np.diff(side[16:, 2:5], axis=0)).max() < 1e-6  # then it stays put
    _, block, angle = _apart(theirs, ours)
    assert block.max() < 2.0 and angle.max() < 1.5  # measured: 1.04 px, 0 degrees


def test_the_block_carries_gym_pushts_mass_moment_and_centre_of_gravity():
    theirs = gym.make(THEIRS).unwrapped
    theirs.reset(seed=0)
    model = build_model(SceneSpec(variant="gym-pusht"))
    tee = model.body("tee").id
    assert model.body_mass[tee] == pytest.approx(theirs.block.mass)
    assert model.body_inertia[tee][2] == pytest.approx(theirs.block.moment * frame.PX**2)  # about the CoG
    # pymunk's centre of gravity in its T's frame (px, y along the stem) against MuJoCo's, mapped to that frame
    cog_px = np.array(theirs.block.center_of_gravity)
    ipos = model.body_ipos[tee][:2] / frame.PX
    assert ipos == pytest.approx([cog_px[0], -(cog_px[1] - frame.ORIGIN_PX)])
    assert model.jnt_pos[model.joint("tee_yaw").id][:2] == pytest.approx(model.body_ipos[tee][:2])  # it turns there


def test_contacts_are_frictionless_and_the_agent_touches_only_the_block():
    model = build_model(SceneSpec(variant="gym-pusht"))
    tip = model.geom("pusher_tip").id
    for g in range(model.ngeom):
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            assert model.geom_condim[g] == 1, model.geom(g).name
    walls = [model.geom(f"wall_{s}").id for s in "nsew"]
    for w in walls:  # gym-pusht's agent is kinematic: walls do not stop it
        assert not (model.geom_contype[tip] & model.geom_conaffinity[w] or model.geom_contype[w] & model.geom_conaffinity[tip])


def test_the_layout_reads_the_origin_of_a_t_that_turns_about_its_centre_of_gravity():
    model = build_model(SceneSpec(variant="gym-pusht"))
    layout = QposLayout.of(model)
    assert layout.anchor is not None
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(-0.2, 0.2, (20, 2)), rng.uniform(-np.pi, np.pi, 20), rng.uniform(-0.2, 0.2, (20, 2))])
    data = mujoco.MjData(model)
    for pose, q in zip(poses, layout.initial_qpos(model, poses)):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        b = model.body("tee").id
        xmat = data.xmat[b].reshape(3, 3)
        np.testing.assert_allclose(data.xpos[b][:2], pose[:2], atol=1e-12)  # MuJoCo's own kinematics
        assert np.arctan2(xmat[1, 0], xmat[0, 0]) == pytest.approx(pose[2], abs=1e-12)
        np.testing.assert_allclose(layout.tee_pose(q), pose[:3], atol=1e-12)
        np.testing.assert_allclose(layout.qpos_of_state(model.qpos0, np.concatenate([pose[3:], pose[:3]])), q, atol=1e-12)
