"""Recordings open with rerun's own reader and hold the chapter's entity paths and timeline."""

from __future__ import annotations

import numpy as np

from mjx_pusht.cli import main


def _contents(path):
    from rerun.chunk import RrdReader

    entities, timelines = set(), set()
    for chunk in RrdReader(str(path)).stream():
        entities.add(str(chunk.entity_path))
        timelines.update(chunk.timeline_names)
    return entities, timelines


def test_scene_recording_has_the_entity_paths_and_sim_time(tmp_path):
    assert main(["scene", "--out", str(tmp_path)]) == 0
    entities, timelines = _contents(tmp_path / "scene.rrd")
    for path in ("/world/objects/tee", "/world/objects/target", "/world/robot/pusher", "/plots/weld_gap/measured"):
        assert path in entities, (path, entities)
    assert "sim_time" in timelines


def test_split_recording_shows_the_stem_as_its_own_entity(tmp_path):
    assert main(["scene", "--break", "split-tee", "--out", str(tmp_path)]) == 0
    entities, _ = _contents(tmp_path / "scene.rrd")
    assert "/world/objects/tee_stem" in entities


def test_replayed_gap_is_the_weld_gap():
    from mjx_pusht.record import replay
    from mjx_pusht.rollout_cpu import run_cpu
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.scene import SceneSpec, build_model

    r = run_cpu(Scenario(SceneSpec("split-tee")), np.array([0]), trace=True)
    poses = replay(build_model(SceneSpec("split-tee")), r.trace.qpos[0])
    # The chapter reads geom_xpos after mj_step, which holds the kinematics MuJoCo
    # computed at the start of that step: after step 40 that is frame 39's state.
    assert abs(poses["gap"][39] - r.gap_settled[0]) < 1e-15
    # and the peak is taken over every state MuJoCo stepped from (all frames but the last)
    assert abs(np.abs(poses["gap"][:-1] - 0.06).max() - r.gap_max_dev[0]) < 1e-15
