"""The CPU backend: MuJoCo C in float64 through `mujoco.rollout` on every core.

This is the determinism reference: each seed's rollout is exactly the chapter's
mj_step loop (fresh warm start, the same controls), so row s of a sweep equals
`mjx-pusht scene --seed s` to the last bit.
"""

from __future__ import annotations

import functools
import os

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjx_pusht.metrics import invariants_init, invariants_update
from mjx_pusht.reset import QposLayout, start_poses
from mjx_pusht.results import Rollouts, Trace
from mjx_pusht.scenario import Scenario
from mjx_pusht.scene import build_model

_STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS
_CHUNK = 4096  # seeds per rollout call: bounds the (chunk, steps, nstate) buffer to ~100 MB


def default_threads() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


@functools.lru_cache(maxsize=8)
def _model(scenario: Scenario) -> mujoco.MjModel:
    return build_model(scenario.scene)


def initial_states(model: mujoco.MjModel, qpos: np.ndarray) -> np.ndarray:
    """(N, nstate) full physics states at rest with the given qpos, as mj_resetData leaves them."""
    data = mujoco.MjData(model)
    size = mujoco.mj_stateSize(model, _STATE_SPEC)
    base = np.empty(size)
    mujoco.mj_getState(model, data, base, _STATE_SPEC)
    states = np.tile(base, (len(qpos), 1))
    states[:, 1 : 1 + model.nq] = qpos  # FULLPHYSICS is [time, qpos, qvel, act, ...]
    return states


def run_cpu(
    scenario: Scenario,
    seeds: np.ndarray,
    *,
    trace: bool = False,
    nthread: int | None = None,
    model: mujoco.MjModel | None = None,
    combos: np.ndarray | None = None,
    poses: np.ndarray | None = None,
) -> Rollouts:
    """Roll out every seed on the CPU and reduce each to its per-seed row.

    `combos[i]` picks row i's parameter combination from `scenario.grid()`; each
    row runs on its own parameterised MjModel (mujoco.rollout takes one per row).
    """
    model = model if model is not None else _model(scenario)
    grid = scenario.grid()
    combos = np.zeros(len(seeds), np.int64) if combos is None else np.asarray(combos, np.int64)
    if scenario.params:
        from mjx_pusht.params import apply

        models = [apply(model, g) for g in grid]
    seeds = np.asarray(seeds, dtype=np.int64)
    nthread = nthread or default_threads()
    layout = QposLayout.of(model)
    schedule = scenario.schedule
    ctrl = schedule.controls()[None]  # (1, T, nu), broadcast over the batch
    bar = slice(0, 3)  # sensor order as authored: bar_pos then stem_pos
    stem = slice(3, 6)
    poses = start_poses(seeds) if poses is None else poses  # a sweep draws them once, for every chunk
    parts, traces = [], []
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    with mj_rollout.Rollout(nthread=nthread) as pool:
        for lo in range(0, len(seeds), _CHUNK):
            qpos0 = layout.initial_qpos(model, poses[lo : lo + _CHUNK])
            n = len(qpos0)
            row_models = [models[c] for c in combos[lo : lo + n]] if scenario.params else model
            state, sensor = pool.rollout(
                row_models, datas, initial_states(model, qpos0), ctrl,
                nstep=schedule.total_steps,
                initial_warmstart=np.zeros((n, model.nv)),  # as a fresh MjData: no carry-over between seeds
            )
            qpos = state[:, :, 1 : 1 + model.nq]
            qvel = state[:, :, 1 + model.nq : 1 + model.nq + model.nv]
            acc = invariants_init(n, np)
            for t in range(schedule.total_steps):
                acc = invariants_update(
                    acc, t, schedule.settle_steps - 1, layout.tee_pose(qpos[:, t]), qpos[:, t], qvel[:, t],
                    sensor[:, t, bar], sensor[:, t, stem],
                )
            parts.append(
                Rollouts(
                    seeds=seeds[lo : lo + n],
                    start=poses[lo : lo + n],
                    settled=acc["tee_settled"],
                    final=layout.tee_pose(qpos[:, -1]),
                    pusher_final=layout.pusher_xy(qpos[:, -1]),
                    gap_settled=acc["gap_settled"],
                    gap_max_dev=acc["gap_max_dev"],
                    finite=acc["finite"],
                    contained=acc["contained"],
                )
            )
            if trace:
                traces.append(np.concatenate([qpos0[:, None], qpos], axis=1))
    out = Rollouts.concat(parts) if parts else _empty()
    if scenario.params:
        out.params = {name: np.array([grid[c][name] for c in combos]) for name, _ in scenario.params}
    if trace:
        out.trace = Trace(np.concatenate(traces), float(model.opt.timestep))
    return out


def _empty() -> Rollouts:
    z = np.zeros((0, 3))
    b = np.zeros(0, bool)
    return Rollouts(np.zeros(0, np.int64), z, z, z, np.zeros((0, 2)), np.zeros(0), np.zeros(0), b, b)
