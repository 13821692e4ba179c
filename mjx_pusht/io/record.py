"""Rerun recordings, made from `Rollouts` traces by replaying MuJoCo's own kinematics.

A trace is just qpos per frame; world poses and the weld gap of each frame come
from mj_kinematics on the model the backend simulated, so a recording looks the
same whichever backend produced it.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from mjx_pusht.backends.results import Rollouts
from mjx_pusht.task.invariants import weld_gap

TEE_COLOR = [115, 128, 242]
STEM_SPLIT_COLOR = [242, 128, 115]
TARGET_COLOR = [90, 204, 102]
PUSHER_COLOR = [230, 102, 89]
WALL_COLOR = [153, 153, 153]
SEED_SPACING = 0.95  # metres between side-by-side workspaces (each is 0.86 m wide)
SERIES_COLORS = {"welded": TEE_COLOR, "split_tee": STEM_SPLIT_COLOR, "free_tee": [230, 200, 60], "measured": TEE_COLOR}


def viewer_command(path: Path) -> str:
    """The command that opens the recording `path`: rerun-sdk installs its viewer beside this Python (a venv's
    bin/), which a venv's user need not have on PATH; bare `rerun` was printed where only .venv/bin/rerun exists."""
    import shutil
    import sys

    here = Path(sys.executable).parent / "rerun"
    on_path = shutil.which("rerun")
    exe = "rerun" if on_path and Path(on_path).resolve() == here.resolve() else str(here) if here.exists() else "rerun"
    return f"{exe} {path}"


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


GAP_RANGE = (0.05, 0.10)  # shows the welded 0.06 m and a split T's ~0.09 m on one fixed axis
DEVIATION_FLOOR = 1e-18  # log10 of an exact 0 (a welded T's deviation) is drawn at -18
RIGID_LOG10 = -4.0  # metrics.RIGID_TOL: a rigid T's peak |gap - 0.06| stays below 1e-4 m


def _world_view(n_worlds: int):
    """The workspace(s) from above: eye over the middle of the row of side-by-side workspaces."""
    import rerun.blueprint as rrb

    cx = (n_worlds - 1) * SEED_SPACING / 2
    height = 0.6 + 1.0 * n_worlds * SEED_SPACING
    return rrb.Spatial3DView(origin="world", name="Workspace from above (target green, tee blue, pusher red)",
                             eye_controls=rrb.EyeControls3D(position=[cx, -0.05, height], look_target=[cx, 0.0, 0.0],
                                                            eye_up=[0.0, 1.0, 0.0]))


def _gap_views():
    import rerun.blueprint as rrb

    return [rrb.TimeSeriesView(origin="plots/weld_gap", name="Weld gap: authored 0.06 m and measured (m)",
                               axis_y=rrb.ScalarAxis(range=GAP_RANGE)),
            rrb.TimeSeriesView(origin="plots/weld_deviation",
                               name="log10 |gap - 0.06 m| (0 drawn at -18); rigid below -4",
                               axis_y=rrb.ScalarAxis(range=(-19.0, 0.0)))]


def blueprint(kind: str, n_worlds: int = 1):  # noqa: C901 - one layout per recording kind
    """The layout a recording opens with: the workspace large, the evidence beside it, every view titled."""
    import rerun.blueprint as rrb

    world = _world_view(n_worlds)
    if kind == "eval":
        side = [rrb.TimeSeriesView(origin="plots/coverage", name="Coverage of the target T (success at 0.95)",
                                   axis_y=rrb.ScalarAxis(range=(0.0, 1.05))),
                rrb.TimeSeriesView(origin="plots/reward", name="Reward at each control step (= coverage)",
                                   axis_y=rrb.ScalarAxis(range=(0.0, 1.05))),
                *_gap_views()]
    else:
        side = _gap_views()
    top = rrb.Horizontal(world, rrb.Vertical(*side), column_shares=[3, 2])
    if kind == "scene":
        return rrb.Blueprint(top, collapse_panels=False)
    if kind == "walk":
        # paused on sim_time: scrub to the first settled frame (0.40 s) and compare the two Ts
        return rrb.Blueprint(top, rrb.TimePanel(timeline="sim_time", play_state="paused", state="expanded"))
    outcomes = [rrb.Spatial2DView(origin="outcomes/final_xy", name="Final tee (x, y) of every seed, north up: straight green, "
                                  "spun ccw blue, cw orange, split red; target T outlined (m)")]
    for name, title in _HISTOGRAMS.items():
        outcomes.append(rrb.BarChartView(origin=f"outcomes/{name}", name=title))
    return rrb.Blueprint(rrb.Vertical(top, rrb.Horizontal(*outcomes), row_shares=[3, 2]))


def _log_deviation(rr, label: str, gap: np.ndarray, times: np.ndarray) -> None:
    tl = rr.TimeColumn("sim_time", duration=times)
    dev = np.log10(np.maximum(np.abs(gap - 0.06), DEVIATION_FLOOR))
    rr.send_columns(f"plots/weld_deviation/{label}", indexes=[tl], columns=rr.Scalars.columns(scalars=dev))


def _log_reference_lines(rr, t_end: float) -> None:
    """The authored 0.06 m gap and the rigidity limit as lines over the whole run."""
    tl = rr.TimeColumn("sim_time", duration=[0.0, t_end])
    rr.log("plots/weld_gap/authored", rr.SeriesLines(colors=[[120, 120, 120]], names=["authored 0.06 m"]), static=True)
    rr.send_columns("plots/weld_gap/authored", indexes=[tl], columns=rr.Scalars.columns(scalars=[0.06, 0.06]))
    rr.log("plots/weld_deviation/rigid_limit", rr.SeriesLines(colors=[[200, 60, 60]], names=["1e-4 m: rigid below"]),
           static=True)
    rr.send_columns("plots/weld_deviation/rigid_limit", indexes=[tl],
                    columns=rr.Scalars.columns(scalars=[RIGID_LOG10, RIGID_LOG10]))


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
    label = plot.rsplit("/", 1)[-1]
    color = SERIES_COLORS.get(label)
    if color is not None:  # the walk's two Ts in their own colours; seeds take the viewer's palette
        rr.log(plot, rr.SeriesLines(colors=[color], names=[label]), static=True)
        rr.log(f"plots/weld_deviation/{label}", rr.SeriesLines(colors=[color], names=[label]), static=True)
    rr.send_columns(plot, indexes=[tl], columns=rr.Scalars.columns(scalars=poses["gap"]))
    _log_deviation(rr, label, poses["gap"], times)


def partial(path: Path) -> Path:
    """Where a recording is written before it is renamed into place."""
    return Path(path).with_name(f".{Path(path).name}.partial")


def record_run(path: Path, model: mujoco.MjModel, rollouts: Rollouts, *, app: str = "mjx_pusht_scene") -> Path:
    """One seed's run at the chapter's entity paths: world/objects/tee, world/objects/target, world/robot/pusher."""
    import rerun as rr

    assert rollouts.trace is not None, "record_run needs a traced rollout"
    rec = rr.RecordingStream(app)
    with rec:
        rec.save(str(partial(path)), default_blueprint=blueprint("scene"))
        _log_static_scene(rr, "world", model)
        _log_frames(rr, "world", model, rollouts.trace.qpos[0], rollouts.trace.dt, "plots/weld_gap/measured")
        _log_reference_lines(rr, (rollouts.trace.qpos.shape[1] - 1) * rollouts.trace.dt)
    rec.flush()
    rec.disconnect()
    partial(path).replace(path)  # whole or not at all: a failed or killed recording leaves no half .rrd
    return path


def record_walk(path: Path, runs: list[tuple[str, mujoco.MjModel, Rollouts]]) -> Path:
    """The chapter's diagnosis walk: the welded and the split T side by side (world/<label>/...),
    both weld gaps on one plot, ready to scrub to the first settled frame."""
    import rerun as rr

    rec = rr.RecordingStream("mjx_pusht_walk")
    with rec:
        rec.save(str(partial(path)), default_blueprint=blueprint("walk", len(runs)))
        for k, (label, model, r) in enumerate(runs):
            root = f"world/{label}"
            rr.log(root, rr.Transform3D(translation=[k * SEED_SPACING, 0, 0]), static=True)
            _log_static_scene(rr, root, model)
            _log_frames(rr, root, model, r.trace.qpos[0], r.trace.dt, f"plots/weld_gap/{label}")
        r = runs[0][2]
        _log_reference_lines(rr, (r.trace.qpos.shape[1] - 1) * r.trace.dt)
    rec.flush()
    rec.disconnect()
    partial(path).replace(path)  # whole or not at all: a failed or killed recording leaves no half .rrd
    return path


def _histogram(values: np.ndarray, bins: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Counts, bin centres and bin widths (in the values' own units) of the finite values."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return np.zeros(bins), np.arange(bins, dtype=float), np.ones(bins)
    counts, edges = np.histogram(finite, bins=bins)
    return counts, 0.5 * (edges[:-1] + edges[1:]), np.diff(edges)


# outcome histograms: entity name under outcomes/ -> the view's title (physical units on the x axis)
_HISTOGRAMS = {
    "final_y_histogram": "Final tee y (m), all seeds",
    "final_yaw_histogram": "Final tee yaw, wrapped to (-pi, pi] (rad), all seeds",
    "log10_gap_max_dev_histogram": "log10 peak |gap - 0.06 m| per seed (0 drawn at -18)",
}
MODE_COLORS = {"straight": [60, 160, 90], "spun_ccw": [70, 110, 230], "spun_cw": [230, 150, 40], "split": [220, 60, 60]}


def _log_outcomes(rr, everyone: Rollouts) -> None:
    """Outcome distributions over every seed, in metres and radians: the final (x, y) coloured by
    outcome mode with the target T outlined, and histograms over bin centres."""
    from mjx_pusht.study.outcomes import modes
    from mjx_pusht.task.rules import T_OUTLINE, wrap_angle

    yaw = wrap_angle(everyone.final[:, 2])  # a turn is a turn, whichever way round the hinge counted it
    mode = modes(yaw)
    mode = np.where(everyone.rigid, mode, "split")
    north_up = np.array([1.0, -1.0])  # 2D views draw +y downward, as images do: flip so north is up
    for name, color in MODE_COLORS.items():
        m = mode == name
        if m.any():
            rr.log(f"outcomes/final_xy/{name}", rr.Points2D(everyone.final[m, :2] * north_up, colors=[color], radii=0.002),
                   static=True)
    outline = np.array(T_OUTLINE + (T_OUTLINE[0],)) * north_up
    rr.log("outcomes/final_xy/target", rr.LineStrips2D([outline], colors=[[90, 204, 102]]), static=True)
    for name, values in (("final_y_histogram", everyone.final[:, 1]), ("final_yaw_histogram", yaw),
                         ("log10_gap_max_dev_histogram", np.log10(np.maximum(everyone.gap_max_dev, DEVIATION_FLOOR)))):
        counts, centres, widths = _histogram(values)
        rr.log(f"outcomes/{name}", rr.BarChart(counts, abscissa=centres, widths=widths), static=True)


def record_sweep(path: Path, model: mujoco.MjModel, traced: Rollouts, everyone: Rollouts,
                 labels: list[str] | None = None) -> Path:
    """K seeds side by side (world/seed_S/...), and outcome distributions over every seed (outcomes/...)."""
    import rerun as rr

    assert traced.trace is not None
    rec = rr.RecordingStream("mjx_pusht_sweep")
    with rec:
        labels = labels or [f"seed_{int(s)}" for s in traced.seeds]
        rec.save(str(partial(path)), default_blueprint=blueprint("sweep", len(labels)))
        for k, label in enumerate(labels):
            root = f"world/{label}"
            rr.log(root, rr.Transform3D(translation=[k * SEED_SPACING, 0, 0]), static=True)
            _log_static_scene(rr, root, model)
            _log_frames(rr, root, model, traced.trace.qpos[k], traced.trace.dt, f"plots/weld_gap/{label}")
        _log_reference_lines(rr, (traced.trace.qpos.shape[1] - 1) * traced.trace.dt)
        _log_outcomes(rr, everyone)
    rec.flush()
    rec.disconnect()
    partial(path).replace(path)  # whole or not at all: a failed or killed recording leaves no half .rrd
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

    from mjx_pusht.model.layout import QposLayout
    from mjx_pusht.task.rules import SUCCESS_COVERAGE, coverage_np

    assert traced.trace is not None and traced.episode is not None
    layout = QposLayout.of(model)
    fs, dt = traced.trace.frame_skip, traced.trace.dt
    rec = rr.RecordingStream("mjx_pusht_eval")
    with rec:
        labels = labels or [f"seed_{int(s)}" for s in traced.seeds]
        rec.save(str(partial(path)), default_blueprint=blueprint("eval", len(labels)))
        rr.log("plots/coverage/success", rr.SeriesLines(colors=[[120, 120, 120]], names=["success at 0.95"]), static=True)
        for k, label in enumerate(labels):
            root = f"world/{label}"
            frames = int(traced.episode["length"][k]) * fs + 1  # the episode's own frames, not what ran after it ended
            qpos = traced.trace.qpos[k, :frames]
            rr.log(root, rr.Transform3D(translation=[k * SEED_SPACING, 0, 0]), static=True)
            _log_static_scene(rr, root, model)
            _log_frames(rr, root, model, qpos, dt, f"plots/weld_gap/{label}")
            goal = traced.episode.get("goal")  # random goals: each episode's own target
            cov = coverage_np(layout.tee_pose(qpos), *(() if goal is None else (goal[k],)))
            tl = rr.TimeColumn("sim_time", duration=np.arange(frames) * dt)
            rr.send_columns(f"plots/coverage/{label}", indexes=[tl], columns=rr.Scalars.columns(scalars=cov))
            # the frame that ends each control step: frame 0 is the start, so L steps end at fs, 2 fs, ..., L fs
            steps = np.arange(1, (len(qpos) - 1) // fs + 1) * fs  # (frames // fs was L + 1 at --frame-skip 1)
            rr.send_columns(f"plots/reward/{label}", indexes=[rr.TimeColumn("sim_time", duration=steps * dt)],
                            columns=rr.Scalars.columns(scalars=cov[steps]))
        tl = rr.TimeColumn("sim_time", duration=[0.0, traced.trace.qpos.shape[1] * dt])
        rr.send_columns("plots/coverage/success", indexes=[tl], columns=rr.Scalars.columns(scalars=[SUCCESS_COVERAGE] * 2))
        _log_reference_lines(rr, (traced.trace.qpos.shape[1] - 1) * dt)
        _log_outcomes(rr, everyone)
    rec.flush()
    rec.disconnect()
    partial(path).replace(path)  # whole or not at all: a failed or killed recording leaves no half .rrd
    return path
