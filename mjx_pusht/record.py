"""Rerun recordings, made from `Rollouts` traces by replaying MuJoCo's own kinematics.

A trace is just qpos per frame; world poses and the weld gap of each frame come
from mj_kinematics on the model the backend simulated, so a recording looks the
same whichever backend produced it.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_pusht.metrics import weld_gap
from mjx_pusht.results import Rollouts

TEE_COLOR = [115, 128, 242]
STEM_SPLIT_COLOR = [242, 128, 115]
TARGET_COLOR = [90, 204, 102]
PUSHER_COLOR = [230, 102, 89]
WALL_COLOR = [153, 153, 153]
SEED_SPACING = 0.95  # metres between side-by-side workspaces (each is 0.86 m wide)


def replay(model: mujoco.MjModel, qpos: np.ndarray) -> dict[str, np.ndarray]:
    """World poses of the moving bodies and the weld gap, per frame of a (T, nq) qpos trace."""
    data = mujoco.MjData(model)
    bodies = [model.body(i).name for i in range(1, model.nbody) if model.body(i).name != "target"]
    ids = {b: model.body(b).id for b in bodies}
    bar, stem = model.geom("tee_bar").id, model.geom("tee_stem").id
    out = {f"{b}_pos": np.zeros((len(qpos), 3)) for b in bodies}
    out |= {f"{b}_quat": np.zeros((len(qpos), 4)) for b in bodies}
    out["gap"] = np.zeros(len(qpos))
    for k, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for b, i in ids.items():
            out[f"{b}_pos"][k] = data.xpos[i]
            out[f"{b}_quat"][k] = data.xquat[i]
        out["gap"][k] = weld_gap(data.geom_xpos[bar], data.geom_xpos[stem])
    return out


def _xyzw(wxyz: np.ndarray) -> np.ndarray:
    return wxyz[..., [1, 2, 3, 0]]


def _log_static_scene(rr, root: str, model: mujoco.MjModel) -> None:
    """Shapes never change: log them once as static, then stream only transforms."""
    split = "tee_stem_body" in {model.body(i).name for i in range(model.nbody)}
    walls = [model.geom(f"wall_{s}") for s in "nsew"]
    rr.log(f"{root}/walls", rr.Boxes3D(half_sizes=[w.size for w in walls], centers=[w.pos for w in walls],
                                     colors=[WALL_COLOR]), static=True)
    rr.log(f"{root}/objects/target", rr.Boxes3D(half_sizes=[[0.06, 0.015, 0.001], [0.015, 0.045, 0.001]],
                                              centers=[[0, 0, 0], [0, -0.06, 0]], colors=[TARGET_COLOR]), static=True)
    if split:
        rr.log(f"{root}/objects/tee", rr.Boxes3D(half_sizes=[[0.06, 0.015, 0.015]], colors=[TEE_COLOR]), static=True)
        rr.log(f"{root}/objects/tee_stem", rr.Boxes3D(half_sizes=[[0.015, 0.045, 0.015]], colors=[STEM_SPLIT_COLOR]),
               static=True)
    else:
        rr.log(f"{root}/objects/tee", rr.Boxes3D(half_sizes=[[0.06, 0.015, 0.015], [0.015, 0.045, 0.015]],
                                                centers=[[0, 0, 0], [0, -0.06, 0]], colors=[TEE_COLOR]), static=True)
    tip = model.geom("pusher_tip")
    radius, half = float(tip.size[0]), float(tip.size[1])
    shape = rr.Capsules3D if int(tip.type[0]) == int(mujoco.mjtGeom.mjGEOM_CAPSULE) else rr.Cylinders3D
    if shape is rr.Cylinders3D:
        rr.log(f"{root}/robot/pusher", rr.Cylinders3D(lengths=[2 * half], radii=[radius], colors=[PUSHER_COLOR]), static=True)
    else:
        rr.log(f"{root}/robot/pusher", rr.Capsules3D(lengths=[2 * half], radii=[radius],
                                                    translations=[[0, 0, -half]], colors=[PUSHER_COLOR]), static=True)


def _log_frames(rr, root: str, model: mujoco.MjModel, qpos: np.ndarray, dt: float, plot: str) -> None:
    poses = replay(model, qpos)
    times = np.arange(len(qpos)) * dt
    tl = rr.TimeColumn("sim_time", duration=times)
    paths = {"tee": "objects/tee", "tee_stem_body": "objects/tee_stem", "pusher": "robot/pusher"}
    for body, path in paths.items():
        if f"{body}_pos" not in poses:
            continue
        rr.send_columns(f"{root}/{path}", indexes=[tl], columns=rr.Transform3D.columns(
            translation=poses[f"{body}_pos"], quaternion=_xyzw(poses[f"{body}_quat"])))
    rr.send_columns(plot, indexes=[tl], columns=rr.Scalars.columns(scalars=poses["gap"]))


def record_run(path: Path, model: mujoco.MjModel, rollouts: Rollouts, *, app: str = "mjx_pusht_scene") -> Path:
    """One seed's run at the chapter's entity paths: world/objects/tee, world/objects/target, world/robot/pusher."""
    import rerun as rr

    assert rollouts.trace is not None, "record_run needs a traced rollout"
    rec = rr.RecordingStream(app)
    with rec:
        rec.save(str(path))
        _log_static_scene(rr, "world", model)
        rr.log("plots/weld_gap/authored", rr.SeriesLines(colors=[[120, 120, 120]], names=["0.06 m weld"]), static=True)
        _log_frames(rr, "world", model, rollouts.trace.qpos[0], rollouts.trace.dt, "plots/weld_gap/measured")
        tl = rr.TimeColumn("sim_time", duration=np.arange(rollouts.trace.qpos.shape[1]) * rollouts.trace.dt)
        rr.send_columns("plots/weld_gap/authored", indexes=[tl],
                        columns=rr.Scalars.columns(scalars=np.full(rollouts.trace.qpos.shape[1], 0.06)))
    rec.flush()
    rec.disconnect()
    return path


def _histogram(values: np.ndarray, bins: int = 40) -> np.ndarray:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return np.zeros(bins)
    counts, _ = np.histogram(finite, bins=bins)
    return counts


def record_sweep(path: Path, model: mujoco.MjModel, traced: Rollouts, everyone: Rollouts,
                 labels: list[str] | None = None) -> Path:
    """K seeds side by side (world/seed_S/...), and outcome distributions over every seed (outcomes/...)."""
    import rerun as rr

    assert traced.trace is not None
    rec = rr.RecordingStream("mjx_pusht_sweep")
    with rec:
        rec.save(str(path))
        labels = labels or [f"seed_{int(s)}" for s in traced.seeds]
        for k, label in enumerate(labels):
            root = f"world/{label}"
            rr.log(root, rr.Transform3D(translation=[k * SEED_SPACING, 0, 0]), static=True)
            _log_static_scene(rr, root, model)
            _log_frames(rr, root, model, traced.trace.qpos[k], traced.trace.dt, f"plots/weld_gap/{label}")
        rigid = everyone.rigid
        colors = np.where(rigid[:, None], [[60, 160, 90]], [[220, 60, 60]])
        rr.log("outcomes/final_xy", rr.Points2D(everyone.final[:, :2], colors=colors, radii=0.002), static=True)
        rr.log("outcomes/final_y_histogram", rr.BarChart(_histogram(everyone.final[:, 1])), static=True)
        rr.log("outcomes/final_yaw_histogram", rr.BarChart(_histogram(everyone.final[:, 2])), static=True)
        rr.log("outcomes/log10_gap_max_dev_histogram",
               rr.BarChart(_histogram(np.log10(np.maximum(everyone.gap_max_dev, 1e-12)))), static=True)
    rec.flush()
    rec.disconnect()
    return path


def recorded_rows(rollouts: Rollouts, k: int) -> np.ndarray:
    """The first k rows, plus split, non-finite or escaped ones (capped at 4*k so a recording stays small)."""
    first = list(range(min(k, len(rollouts))))
    bad = ~rollouts.rigid | ~rollouts.contained
    odd = [i for i in np.flatnonzero(bad) if i >= k]
    return np.array(first + odd[: 4 * max(k, 1)], dtype=np.int64)


def row_labels(rollouts: Rollouts, rows: np.ndarray) -> list[str]:
    """Entity names: seed_S, with the swept parameter values appended when there are any."""
    out = []
    for i in rows:
        label = f"seed_{int(rollouts.seeds[i])}"
        for name, v in (rollouts.params or {}).items():
            label += f"_{name}_{v[i]:g}".replace(".", "p")
        out.append(label)
    return out


def record_episodes(path: Path, model: mujoco.MjModel, traced: Rollouts, everyone: Rollouts,
                    labels: list[str] | None = None) -> Path:
    """Closed-loop episodes side by side (world/seed_S/...), their coverage and reward over sim_time
    (plots/coverage/seed_S, plots/reward/seed_S), and the outcome over every episode (outcomes/...)."""
    import rerun as rr

    from mjx_pusht.reset import QposLayout
    from mjx_pusht.task import SUCCESS_COVERAGE, coverage_np

    assert traced.trace is not None and traced.episode is not None
    layout = QposLayout.of(model)
    fs, dt = traced.trace.frame_skip, traced.trace.dt
    rec = rr.RecordingStream("mjx_pusht_eval")
    with rec:
        rec.save(str(path))
        labels = labels or [f"seed_{int(s)}" for s in traced.seeds]
        rr.log("plots/coverage/success", rr.SeriesLines(colors=[[120, 120, 120]], names=["success at 0.95"]), static=True)
        for k, label in enumerate(labels):
            root = f"world/{label}"
            frames = int(traced.episode["length"][k]) * fs + 1  # the episode's own frames, not what ran after it ended
            qpos = traced.trace.qpos[k, :frames]
            rr.log(root, rr.Transform3D(translation=[k * SEED_SPACING, 0, 0]), static=True)
            _log_static_scene(rr, root, model)
            _log_frames(rr, root, model, qpos, dt, f"plots/weld_gap/{label}")
            cov = coverage_np(layout.tee_pose(qpos))
            tl = rr.TimeColumn("sim_time", duration=np.arange(frames) * dt)
            rr.send_columns(f"plots/coverage/{label}", indexes=[tl], columns=rr.Scalars.columns(scalars=cov))
            steps = np.arange(1, frames // fs + 1) * fs  # the frame that ends each control step
            rr.send_columns(f"plots/reward/{label}", indexes=[rr.TimeColumn("sim_time", duration=steps * dt)],
                            columns=rr.Scalars.columns(scalars=cov[steps]))
        tl = rr.TimeColumn("sim_time", duration=[0.0, traced.trace.qpos.shape[1] * dt])
        rr.send_columns("plots/coverage/success", indexes=[tl], columns=rr.Scalars.columns(scalars=[SUCCESS_COVERAGE] * 2))
        ok = np.asarray(everyone.episode["success"], bool)
        colors = np.where(ok[:, None], [[60, 160, 90]], [[220, 60, 60]])
        rr.log("outcomes/final_xy", rr.Points2D(everyone.final[:, :2], colors=colors, radii=0.002), static=True)
        rr.log("outcomes/final_coverage_histogram", rr.BarChart(_histogram(np.asarray(everyone.episode["coverage"]))),
               static=True)
    rec.flush()
    rec.disconnect()
    return path
