"""The CPU backend: MuJoCo C in float64, the determinism reference.

Each seed's rollout is exactly the chapter's mj_step loop (a fresh MjData, the warm start
carried from step to step), so row s of a sweep equals `mjx-pusht scene --seed s` to the
last bit. The rollout itself is `episode.py`'s, shared with MJX; this module only steps
MuJoCo, in one of two ways that give the same bits:

- a controller that ignores its observation (`open_loop`) is rolled out in one
  `mujoco.rollout` call on every core, and its commands are checked step by step against
  what the controller says while the rollout is replayed;
- a feedback controller steps one MjData per seed between control steps (`mj_step` holds
  Python's lock between physics steps, so this runs on one core).
"""

from __future__ import annotations

import functools
import os

import mujoco
import numpy as np
from mujoco import rollout as mj_rollout

from mjx_pusht.api import run_options
from mjx_pusht.backends import actions
from mjx_pusht.backends.base import Backend, drawn_params
from mjx_pusht.backends.results import Rollouts, Trace, from_carry
from mjx_pusht.model.layout import QposLayout
from mjx_pusht.model.scene import build_model
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.controllers import seed_key
from mjx_pusht.task.episode import act, after_physics_steps, begin, control_step
from mjx_pusht.task.reset import start_poses

_STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS
_CHUNK = 4096  # seeds per rollout call: bounds the (chunk, steps, nstate) buffer to ~100 MB


def default_threads() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


@functools.lru_cache(maxsize=8)
def cpu_model(scenario: Scenario) -> mujoco.MjModel:
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


class _Replay:
    """An open-loop batch: the whole trajectory from `mujoco.rollout`, handed out one control step at a time."""

    def __init__(self, pool, models, datas, model, qpos0, ctrl, frame_skip):
        n = len(qpos0)
        self.ctrl, self.fs, self.k = ctrl, frame_skip, 0
        state, self.sens = pool.rollout(
            models, datas, initial_states(model, qpos0), np.repeat(ctrl, frame_skip, axis=0)[None],
            initial_warmstart=np.zeros((n, model.nv)),  # as a fresh MjData: no carry-over between seeds
        )
        self.qpos = state[:, :, 1 : 1 + model.nq]
        self.qvel = state[:, :, 1 + model.nq : 1 + model.nq + model.nv]
        # mujoco.rollout stops a world at its first MuJoCo warning and repeats its last state to the
        # end, without handing back which warning: its clock stops. mj_step would have carried on.
        clock = np.arange(1, state.shape[1] + 1) * model.opt.timestep
        self.stopped = ~np.all(np.abs(state[:, :, 0] - clock) <= 1e-9 * clock, axis=1)

    def warnings(self) -> np.ndarray:
        return np.zeros(len(self.stopped), np.int32)  # a world that raised one stopped (and was rerun by _Lockstep)

    def advance(self, u, live):
        if not np.array_equal(u[live], np.broadcast_to(self.ctrl[self.k], u[live].shape)):
            raise RuntimeError("an open-loop controller commanded something other than its open_loop() table")
        s = slice(self.k * self.fs, (self.k + 1) * self.fs)
        self.k += 1
        return self.qpos[:, s].swapaxes(0, 1), self.qvel[:, s].swapaxes(0, 1), self.sens[:, s].swapaxes(0, 1)


class _Lockstep:
    """A feedback batch: one MjData per seed, stepped `frame_skip` times per control step.

    With `threads` > 1 the worlds are stepped in that many slices at once: mj_step lets go of
    Python's lock while it runs, and each world is still its own MjData, so the bits are the
    same as one thread's (test).
    """

    def __init__(self, models, model, qpos0, frame_skip, threads: int = 1):
        self.models = models if isinstance(models, list) else [model] * len(qpos0)
        self.datas = []
        for m, q in zip(self.models, qpos0):
            d = mujoco.MjData(m)
            d.qpos[:] = q
            self.datas.append(d)
        self.fs, self.threads = frame_skip, threads
        n = len(qpos0)
        self.qpos = np.repeat(np.asarray(qpos0, np.float64)[None], frame_skip, axis=0)  # rows never stepped stay put
        self.qvel = np.zeros((frame_skip, n, model.nv))
        self.sens = np.zeros((frame_skip, n, model.nsensordata))

    def warnings(self) -> np.ndarray:
        """Per world: the MuJoCo warnings its steps raised (a bitmask, see params.warning_bits)."""
        from mjx_pusht.model.params import warning_bits

        return np.array([warning_bits(d) for d in self.datas], np.int32)

    def copy(self) -> _Lockstep:
        """An independent copy (each MjData copied), so an earlier state can be stepped again."""
        new = object.__new__(_Lockstep)
        new.models, new.fs, new.threads = self.models, self.fs, self.threads
        new.datas = [mujoco.MjData(m) for m in self.models]
        for m, src, dst in zip(self.models, self.datas, new.datas):
            mujoco.mj_copyData(dst, m, src)
        new.qpos, new.qvel, new.sens = self.qpos.copy(), self.qvel.copy(), self.sens.copy()
        new._view_cache = None
        return new

    def splice(self, rows, other: _Lockstep, inplace: bool = False) -> _Lockstep:
        """This batch with `rows` taken from `other` (a batch of len(rows) worlds): a partial reset."""
        new = self if inplace else self.copy()
        for j, i in enumerate(np.asarray(rows)):
            if other.models[j] is not new.models[i]:  # a new episode's own physics (randomised): its model too
                new.models = [*new.models[:i], other.models[j], *new.models[i + 1:]]
                new._view_cache = None
            mujoco.mj_copyData(new.datas[i], other.models[j], other.datas[j])
            new.qpos[:, i], new.qvel[:, i], new.sens[:, i] = other.qpos[:, j], other.qvel[:, j], other.sens[:, j]
        return new

    def _views(self):
        """Per world: (model, data, and NumPy views of its ctrl, qpos, qvel, sensordata), made once: each
        attribute read of an MjData builds a new array, which cost more than the copy it fed (an MjData's
        buffers never move, and `splice` copies into the same MjData)."""
        if getattr(self, "_view_cache", None) is None or len(self._view_cache) != len(self.datas):
            self._view_cache = [(m, d, d.ctrl, d.qpos, d.qvel, d.sensordata) for m, d in zip(self.models, self.datas)]
        return self._view_cache

    def _step_rows(self, u, rows):
        step, views = mujoco.mj_step, self._views()
        for i in rows:
            m, d, ctrl, q, v, s = views[i]
            ctrl[:] = u[i]
            qs, vs, ss = self.qpos[:, i], self.qvel[:, i], self.sens[:, i]
            for j in range(self.fs):
                step(m, d)
                qs[j] = q
                vs[j] = v
                ss[j] = s

    def advance(self, u, live):
        rows = np.flatnonzero(live)  # an ended episode is not stepped: nothing it does is kept
        if self.threads > 1 and len(rows) >= 2 * self.threads:
            list(_thread_pool(self.threads).map(lambda r: self._step_rows(u, r), np.array_split(rows, self.threads)))
        else:
            self._step_rows(u, rows)
        return self.qpos, self.qvel, self.sens


def cpu_physics(layout, frame_skip: int, settle_step: int):
    """The CPU side of `task.episode.control_step`: `physics((stepper, _), u, carry, k)` steps every live world
    `frame_skip` times and folds each physics step into the invariants. `k` may be per world (an env's rows
    are at different steps). The sim it hands back is (stepper, the (frame_skip, N, nq) qpos of this step)."""

    steps = np.arange(frame_skip)

    def physics(sim, u, carry, k):
        stepper = sim[0]
        qs, vs, ss = stepper.advance(u, ~carry["ep"]["done"])
        # the frame_skip physics steps folded into the invariants at once (the same bits as one by one)
        t = np.asarray(k)[None] * frame_skip + (steps[:, None] if np.ndim(k) else steps)
        carry = after_physics_steps(carry, t, settle_step, layout, qs, vs, ss, np)
        return qs[-1].copy(), carry, (stepper, qs)

    return physics


@functools.lru_cache(maxsize=4)
def _thread_pool(threads: int):
    from concurrent.futures import ThreadPoolExecutor

    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="mj_step")


class FeedbackPool:
    """Feedback episodes over several processes: MuJoCo C steps one seed's MjData at a time while holding
    Python's lock, so a batch on one process uses one core. Each worker runs `run_cpu` on a slice of the seeds;
    the rows are the same bits as one process (every seed is its own MjData).

    Workers are spawned, so they re-import the caller's main module: a script that makes one at its top level,
    outside `if __name__ == "__main__":`, would start itself again in every worker, and is refused in one line
    instead. Workers exit when their parent does, whatever killed it."""

    def __init__(self, workers: int):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        _refuse_unguarded_main(workers)
        # One BLAS thread per worker (spawned workers inherit the environment and read it when NumPy loads):
        # a trained policy's matrix products run in every worker, and OpenBLAS's default of one thread per
        # core in each of `workers` processes oversubscribed a 16-core host (the C side of a 4,096-episode
        # compare with a 1024-wide policy did not finish in 400 s, notebook change 12). A user's setting wins.
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        self.workers, self.jobs = workers, []
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                        initializer=_die_with_parent, initargs=(os.getpid(),))
        FeedbackPool.live.add(self)

    live: set = set()  # the pools not yet closed: an interrupted command ends them (cli.commands.end_interrupted)

    def run(self, scenario: Scenario, seeds, *, combos=None, poses=None) -> Rollouts:
        seeds = np.asarray(seeds, np.int64)
        combos = np.zeros(len(seeds), np.int64) if combos is None else np.asarray(combos, np.int64)
        poses = start_poses(seeds, reset=scenario.reset) if poses is None else poses
        parts = np.array_split(np.arange(len(seeds)), min(len(seeds), 4 * self.workers))
        self.jobs = jobs = [self.pool.submit(run_cpu, scenario, seeds[i], nthread=1, combos=combos[i], poses=poses[i])
                            for i in parts if len(i)]
        bad = [j.exception() for j in jobs if isinstance(j.exception(), actions.NonFiniteActionError)]
        if bad:  # as one process would: the earliest control step of any slice, then the first slice
            raise actions.earliest(bad)
        return Rollouts.concat([j.result() for j in jobs])

    def close(self, end: bool = False) -> None:
        """Shut the workers down. Unfinished episodes (^C, or `end`) are unwanted: their workers are ended, as
        shutdown would wait for them, and a user's controller may be busy for minutes."""
        FeedbackPool.live.discard(self)
        if end or not all(j.done() for j in self.jobs):
            for proc in list((getattr(self.pool, "_processes", None) or {}).values()):
                proc.terminate()
        self.pool.shutdown(cancel_futures=True)


def _die_with_parent(parent: int) -> None:
    """In a worker: exit as soon as the process that made it is gone (a kill -9 leaves no handler to
    shut the pool down, and orphaned workers lived on under PID 1 for minutes, ~94 MB each)."""
    import threading
    import time

    def watch():
        while os.getppid() == parent:
            time.sleep(0.2)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="die-with-parent").start()


def _refuse_unguarded_main(workers: int) -> None:
    """Refuse, in one line, to spawn workers from a script's top level outside its `__main__` guard:
    each worker would run the script again (and the pool break with BrokenProcessPool)."""
    import ast
    import sys
    from pathlib import Path

    from mjx_pusht.errors import ConfigError

    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    frame = sys._getframe(1)
    while frame is not None and not (frame.f_globals is getattr(main, "__dict__", None) and frame.f_code.co_name == "<module>"):
        frame = frame.f_back
    if frame is None or path is None or getattr(main, "__spec__", None) is not None:
        return  # not running the script's top level (or run with -m, whose guard the module has)
    try:
        tree = ast.parse(Path(path).read_text())
    except (OSError, SyntaxError):
        return
    line = frame.f_lineno
    for node in ast.walk(tree):
        if (isinstance(node, ast.If) and "__main__" in ast.unparse(node.test) and "__name__" in ast.unparse(node.test)
                and node.lineno <= line <= node.end_lineno):
            return
    raise ConfigError(f"workers={workers} spawns processes that import {path} again, and line {line} runs outside "
                      "`if __name__ == \"__main__\":`; put the call under that guard, or pass workers=1")


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
    """Roll out every seed on the CPU under the scenario's controller and reduce each to its per-seed row.

    `combos[i]` picks row i's parameter combination from `scenario.grid()`; each row runs on
    its own parameterised MjModel.
    """
    model = model if model is not None else cpu_model(scenario)
    grid = scenario.grid()
    combos = np.zeros(len(seeds), np.int64) if combos is None else np.asarray(combos, np.int64)
    from mjx_pusht.model.params import apply, model_warnings

    seeds = np.asarray(seeds, dtype=np.int64)
    if scenario.randomize:  # a model per row, its physics drawn from its seed (model/randomize.py)
        from mjx_pusht.model.randomize import factors, row_models as drawn

        models, combos = drawn(model, scenario.randomize, factors(scenario.randomize, seeds)), np.arange(len(seeds))
    else:
        models = [apply(model, g) for g in grid] if scenario.params else [model]
    model_bits = np.array([model_warnings(m) for m in models], np.int32)  # a singular model, say
    nthread = nthread or default_threads()
    layout = QposLayout.of(model)
    controller, episode = scenario.driver()
    fs = episode.frame_skip
    table = controller.open_loop(episode.max_steps, fs)
    if table is not None and not np.isfinite(table).all():
        table = None  # stepped world by world instead, so the step check below names the seed and step
    settle_step = scenario.schedule.settle_steps - 1
    poses = start_poses(seeds, reset=scenario.reset) if poses is None else poses  # a sweep draws them once
    parts, traces = [], []
    datas = [mujoco.MjData(model) for _ in range(nthread)]
    renderer = None
    if controller.pixels:  # a controller that looks: the top camera's image of every control step's pose
        from mjx_pusht.render.pixels import CpuRenderer

        renderer = CpuRenderer(model, controller.pixels)
    with mj_rollout.Rollout(nthread=nthread) as pool:
        for lo in range(0, len(seeds), _CHUNK):
            qpos0 = layout.initial_qpos(model, poses[lo : lo + _CHUNK])
            n = len(qpos0)
            row_models = [models[c] for c in combos[lo : lo + n]] if scenario.params or scenario.randomize else model
            stepper = _Replay(pool, row_models, datas, model, qpos0, table, fs) if table is not None else None
            if stepper is None or stepper.stopped.any():
                # feedback, or a rollout MuJoCo stopped at a warning: step MjData by MjData, as mj_step
                # does (the same bits as the rollout where it did not stop), and read each world's warnings
                stepper = _Lockstep(row_models, model, qpos0, fs)
            key = seed_key(seeds[lo : lo + n])
            carry = begin(layout, qpos0, key, controller, episode, np)
            physics = cpu_physics(layout, fs, settle_step)
            qpos, frames = qpos0, [qpos0[:, None]]
            for k in range(episode.max_steps):
                if table is None and carry["ep"]["done"].all() and not trace:
                    break  # every episode has ended: the rest would change nothing
                image = None if renderer is None else renderer(qpos, carry.get("goal"))  # the target at each goal
                action, carry = act(carry, qpos, k, key, controller, layout, np, image)
                # every control step, before the physics: the first non-finite action stops the run
                action, bad = actions.record_update(actions.record_init((n,), np.float64, np),
                                                    actions.as_numbers(action, controller.name),
                                                    ~carry["ep"]["done"], k, np)
                actions.check(bad, seeds[lo : lo + n], controller.name)
                qpos, carry, (_, qs) = control_step((stepper, None), carry, qpos, k, action, controller.action_type,
                                                    physics, layout, episode, np)
                if trace:
                    frames.append(qs.swapaxes(0, 1).copy())
            parts.append(from_carry(seeds[lo : lo + n], poses[lo : lo + n], layout.pusher_xy(qpos0), carry))
            parts[-1].warnings = stepper.warnings() | model_bits[combos[lo : lo + n]]
            if trace:
                traces.append(np.concatenate(frames, axis=1))
    out = Rollouts.concat(parts) if parts else Rollouts.empty()
    out.params = drawn_params(scenario, model, seeds, combos)
    if trace:
        out.trace = Trace(np.concatenate(traces), float(model.opt.timestep), fs)
    return out


class CpuBackend(Backend):
    """MuJoCo C, float64, every core: the determinism reference."""

    name = "cpu"
    collisions = {"box-box": "mjc_BoxBox (primitive)", "box-cylinder": "mjc_Convex (native CCD)"}

    def __init__(self, scenario: Scenario, nthread: int | None = None, workers: int = 1):
        self.scenario = scenario
        self.simulated_scene = scenario.scene
        self.nthread = nthread or default_threads()
        # processes for feedback controllers (FeedbackPool); 1: this process only
        self.workers = workers
        self.model = cpu_model(scenario)
        self.devices = ["cpu"]
        self._pool = None

    @property
    def device(self) -> str:
        return f"cpu ({self.nthread} threads)"

    def run(self, seeds, *, trace: bool = False, batch: int | None = None, combos=None, poses=None) -> Rollouts:
        seeds, combos, poses = run_options(self.scenario, seeds, batch, combos, poses)  # the API's: the CLI's checks
        controller, episode = self.scenario.driver()
        feedback = controller.open_loop(episode.max_steps, episode.frame_skip) is None
        if feedback and self.workers > 1 and not trace and len(seeds) >= 2 * self.workers:
            if self._pool is None:
                self._pool = FeedbackPool(self.workers)
            return self._pool.run(self.scenario, seeds, combos=combos, poses=poses)
        return run_cpu(self.scenario, seeds, trace=trace, nthread=self.nthread, model=self.model, combos=combos,
                       poses=poses)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None
