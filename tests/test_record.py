"""Recordings open with rerun's own reader and hold the chapter's entity paths and timeline."""

from __future__ import annotations

import numpy as np

from mjx_pusht.cli.commands import main
from mjx_pusht.io.outputs import read_table


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
    from mjx_pusht.backends.cpu import run_cpu
    from mjx_pusht.io.record import replay
    from mjx_pusht.model.scene import SceneSpec, build_model
    from mjx_pusht.scenario import Scenario

    r = run_cpu(Scenario(SceneSpec("split-tee")), np.array([0]), trace=True)
    poses = replay(build_model(SceneSpec("split-tee")), r.trace.qpos[0])
    # The chapter reads geom_xpos after mj_step, which holds the kinematics MuJoCo
    # computed at the start of that step: after step 40 that is frame 39's state.
    assert abs(poses["gap"][39] - r.gap_settled[0]) < 1e-15
    # and the peak is taken over every state MuJoCo stepped from (all frames but the last)
    assert abs(np.abs(poses["gap"][:-1] - 0.06).max() - r.gap_max_dev[0]) < 1e-15


# --- blueprints: what a person sees when a recording opens ------------------------------------------
def _views(path):
    """The recording's default blueprint, read back with rerun's reader: {origin: view properties}."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    stores = reader.blueprints()
    assert stores, f"{path} carries no blueprint"
    props: dict[str, dict] = {}
    for chunk in reader.stream(store=stores[0]):
        entity = str(chunk.entity_path)
        if not entity.startswith("/view/"):
            continue
        view = entity.split("/")[2]
        rb = chunk.to_record_batch()
        for field in rb.schema:
            if ":" in field.name:
                value = rb.column(field.name).to_pylist()[-1]
                props.setdefault(view, {})[field.name.split(":")[-1]] = value[0] if isinstance(value, list) and len(value) == 1 else value
    return {"/" + p["space_origin"].lstrip("/"): p for p in props.values() if "space_origin" in p}


def _scalars(path, entity):
    from rerun.chunk import RrdReader

    out = []
    for chunk in RrdReader(str(path)).stream():
        if str(chunk.entity_path) == entity:
            rb = chunk.to_record_batch()
            cols = [f.name for f in rb.schema if f.name.endswith("scalars")]  # (a SeriesLines chunk has none)
            if cols:
                out += [v[0] for v in rb.column(cols[0]).to_pylist()]
    return np.array(out)


def test_scene_recording_opens_on_the_workspace_from_above_and_a_gap_plot_with_a_fixed_range(tmp_path):
    assert main(["scene", "--out", str(tmp_path)]) == 0
    views = _views(tmp_path / "scene.rrd")
    world = views["/world"]
    assert "3D" in world["class_identifier"] and world["display_name"].startswith("Workspace from above")
    assert world["position"][2] > 0.5 and world["look_target"][2] == 0.0  # the eye above the table, looking down
    gap = views["/plots/weld_gap"]
    lo, hi = gap["range"]
    assert lo < 0.06 < 0.0912 < hi and "authored 0.06 m" in gap["display_name"]  # welded and split on one axis
    assert "-4" in views["/plots/weld_deviation"]["display_name"]
    measured = _scalars(tmp_path / "scene.rrd", "/plots/weld_gap/measured")
    assert np.allclose(measured, 0.06, atol=1e-12)  # flat at 0.06: the autoscaled noise is gone with the fixed range
    dev = _scalars(tmp_path / "scene.rrd", "/plots/weld_deviation/measured")
    assert (dev < -4).all()  # the welded T's deviation sits below the rigidity line


def test_walk_puts_the_welded_and_split_gaps_on_one_plot(tmp_path):
    assert main(["scene", "--break", "split-tee", "--compare-welded", "--out", str(tmp_path)]) == 0
    entities, _ = _contents(tmp_path / "walk.rrd")
    assert {"/world/welded/objects/tee", "/world/split_tee/objects/tee_stem"} <= entities
    welded = _scalars(tmp_path / "walk.rrd", "/plots/weld_gap/welded")
    split = _scalars(tmp_path / "walk.rrd", "/plots/weld_gap/split_tee")
    assert np.allclose(welded, 0.06, atol=1e-12)
    assert abs(split[40] - 0.0912) < 5e-4  # the first settled frame: the chapter's 0.0912 m
    assert "/plots/weld_gap" in _views(tmp_path / "walk.rrd")


def test_sweep_outcomes_are_in_metres_and_radians_with_titled_views(tmp_path):
    out = tmp_path / "sweep"
    assert main(["sweep", "--seeds", "32", "--backend", "cpu", "--out", str(out), "--no-progress"]) == 0
    views = _views(out / "sweep.rrd")
    for origin in ("/outcomes/final_y_histogram", "/outcomes/final_yaw_histogram", "/outcomes/log10_gap_max_dev_histogram",
                   "/outcomes/final_xy", "/world", "/plots/weld_gap", "/plots/weld_deviation"):
        assert views[origin]["display_name"], origin
    assert "(m)" in views["/outcomes/final_y_histogram"]["display_name"]
    from rerun.chunk import RrdReader

    table = read_table(out / "per_seed.parquet")
    for chunk in RrdReader(str(out / "sweep.rrd")).stream():
        if str(chunk.entity_path) == "/outcomes/final_y_histogram":
            rb = chunk.to_record_batch()
            col = [f.name for f in rb.schema if f.name.endswith("abscissa")][0]
            centres = np.array(rb.column(col).to_pylist()[0][0]["buffer"])
            # bin centres in metres, spanning the seeds' final y, not bin numbers 0..40
            assert table["tee_final_y"].min() <= centres.min() and centres.max() <= table["tee_final_y"].max()
            break
    else:
        raise AssertionError("no final-y histogram")
