"""gym-pusht itself as a backend: the `gym-pusht` task's episodes run in gym-pusht 0.1.8's own env (pymunk).

Every figure on gym-pusht's task can be checked on the original: `eval --task gym-pusht --backend gym-pusht`
runs the same controller (a built-in, a trained policy, a user's function) from the same seeds, and a seed
gives gym-pusht's own `reset(seed=seed)` start, as it does on the drop-in. Nothing of this project's physics
runs: the controller sees what gym-pusht's `reset`/`step` return (its state observation, the angle wrapped to
[0, 2 pi), or its rendered image and `agent_pos`) through task/gym_pusht_obs.py, the door `GymPushtPolicy` puts
a user's plain gym-pusht loop through, and its targets go to gym-pusht's `step` as that door makes them; success
is gym-pusht's `is_success`, coverage its `coverage`.

The episodes spread over a process per core (spawn), each stepping its share of the seeds in lockstep, so a
controller acts once a control step for all of them (a trained policy's batch, not one call an env).
The rows carry what gym-pusht can say: poses, success, coverage; its T is one rigid pymunk body, so the
weld gap is the welded T's by construction (deviation 0), and `finite` and `contained` are checked on its
state. A trace (recordings, videos) places gym-pusht's poses, one a control step, in the variant's MjModel.
"""

from __future__ import annotations

import os

import numpy as np

from mjx_pusht.api import run_options
from mjx_pusht.backends.base import Backend, BackendError
from mjx_pusht.backends.results import Rollouts, Trace
from mjx_pusht.model import gym_pusht as frame

GAP = 0.06  # the welded T's bar-to-stem distance (task/invariants.py), pymunk's one body keeps it exactly


def gym_pusht_available() -> bool:
    try:
        import gym_pusht  # noqa: F401
    except ImportError:
        return False
    return True


class GymPushtBackend(Backend):
    name = "gym-pusht"
    default_chunk = 1024

    def __init__(self, scenario, workers: int | None = None):
        from mjx_pusht.backends.cpu import cpu_model

        if not gym_pusht_available():
            raise BackendError("the gym-pusht backend runs gym-pusht itself: pip install 'gym-pusht==0.1.8'")
        if scenario.scene.variant != "gym-pusht" or scenario.reset != "gym-pusht" or scenario.controller is None:
            raise BackendError("the gym-pusht backend runs gym-pusht's task only (eval --task gym-pusht): a "
                               "controller's episodes from gym-pusht's starts")
        if scenario.params or scenario.randomize:
            raise BackendError("the gym-pusht backend runs gym-pusht's own physics: --param and --randomize vary "
                               "MuJoCo's")
        _, episode = scenario.driver()
        if episode.frame_skip != 10:
            raise BackendError("gym-pusht steps 10 physics steps a control step: --frame-skip 10 only")
        self.scenario, self.simulated_scene = scenario, scenario.scene
        self.model = cpu_model(scenario)  # for recordings: gym-pusht's poses drawn in the variant's scene
        self.devices = ["cpu"]
        self.workers = max(1, workers or len(os.sched_getaffinity(0)))
        self._pool = None

    @property
    def pusher(self) -> str:
        return "gym-pusht (pymunk circle)"

    def run(self, seeds, *, trace: bool = False, batch: int | None = None, combos=None, poses=None) -> Rollouts:
        seeds, combos, poses = run_options(self.scenario, seeds, batch, combos, poses)  # the API's: checked
        idx = [i for i in np.array_split(np.arange(len(seeds)), min(self.workers, max(len(seeds), 1))) if len(i)]
        args = [(self.scenario, seeds[i], trace, None if poses is None else np.asarray(poses)[i]) for i in idx]
        if len(args) <= 1:
            outs = [episodes(*a) for a in args]
        else:  # the CPU backend's worker pool: spawned, one BLAS thread each, refused from an unguarded script
            if self._pool is None:
                from mjx_pusht.backends.cpu import FeedbackPool

                self._pool = FeedbackPool(self.workers)
            outs = [job.result() for job in [self._pool.pool.submit(episodes, *a) for a in args]]
        rows = Rollouts.concat([o for o, _ in outs]) if outs else Rollouts.empty()
        if trace:
            rows.trace = self._trace([q for _, q in outs])
        return rows

    def _trace(self, poses: list[np.ndarray]) -> Trace:
        """Each control step's (pusher, tee) state as the variant's qpos, held for its frame_skip physics frames."""
        from mjx_pusht.model.layout import QposLayout

        _, episode = self.scenario.driver()
        states = np.concatenate(poses)  # (N, steps + 1, 5) observe's order: pusher x, y, tee x, y, yaw
        qpos = QposLayout.of(self.model).qpos_of_state(self.model.qpos0, states)
        held = np.repeat(qpos[:, 1:], episode.frame_skip, axis=1)
        return Trace(np.concatenate([qpos[:, :1], held], axis=1), dt=float(self.model.opt.timestep),
                     frame_skip=episode.frame_skip)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.close()
            self._pool = None


def world_state(env) -> np.ndarray:
    """gym-pusht's agent and block as a state row: pusher x, y, tee x, y, yaw (world frame, metres), read from
    pymunk's bodies for the rows and traces, never for a controller."""
    agent = frame.to_world(np.array([tuple(env.agent.position)], np.float64))
    tee = frame.pose_to_world(np.array([tuple(env.block.position)], np.float64), np.array([env.block.angle]))
    return np.concatenate([agent, tee], axis=-1)[0]


def episodes(scenario, seeds: np.ndarray, trace: bool = False, poses=None):
    """Each seed's episode in its own gym-pusht env, all stepped in lockstep under the scenario's controller.
    `poses`: the starts this project draws for the seeds (task/reset.py), checked against gym-pusht's own.
    Returns (Rollouts, (N, steps + 1, 5) states after each control step when `trace`, else None)."""
    from gym_pusht.envs.pusht import PushTEnv

    from mjx_pusht.task.controllers import seed_key
    from mjx_pusht.task.goals import draw
    from mjx_pusht.task.gym_pusht_obs import controller_obs, gym_pusht_action
    from mjx_pusht.task.rules import episode_init, wrap_angle

    controller, episode = scenario.driver()
    n, image = len(seeds), controller.pixels
    obs_type = "pixels_agent_pos" if image else "state"
    kw = {"observation_width": image, "observation_height": image} if image else {}
    envs = [PushTEnv(obs_type=obs_type, **kw) for _ in range(n)]
    for env in envs:
        # gym-pusht fixes its success_threshold at 0.95 in __init__ (no kwarg: gym-pusht#24) and reads the attribute
        # each step (reward clip(coverage / threshold), is_success coverage > threshold): set, it judges at ours
        env.success_threshold = episode.success
    seen = [env.reset(seed=int(seed))[0] for env, seed in zip(envs, seeds)]  # what gym-pusht returns, per env
    state = np.stack([world_state(e) for e in envs])
    if poses is not None:  # the same seed must start in the same place here as on every other backend
        ours = np.asarray(poses, np.float64)[:, [3, 4, 0, 1, 2]]
        off = np.abs(state - ours)
        off[:, 4] = np.abs(wrap_angle(state[:, 4] - ours[:, 4]))
        if not (off < 1e-9).all():
            bad = np.flatnonzero(~(off < 1e-9).all(-1))
            raise BackendError(f"gym-pusht started seeds {seeds[bad][:8].tolist()} elsewhere than task/reset.py "
                               f"draws them (off by up to {off.max():.3g})")
    key = seed_key(seeds)
    goal = None if episode.goal is None else draw(key, episode.goal, np.float64)  # as every backend draws it
    if goal is not None:  # gym-pusht scores coverage against, and draws, its goal_pose, which its reset put back
        for env, origin, angle in zip(envs, *frame.pose_to_px(goal)):
            env.goal_pose = np.array([*origin, angle])
    carry = controller.init(key)
    start, pusher_start = state[:, 2:5].copy(), state[:, 0:2].copy()
    live = np.ones(n, bool)
    # gym-pusht scores a start on the goal by its first step: the episode runs (as the drop-in's, task/tasks.py)
    ep = episode_init(np.array([e._get_coverage() for e in envs]), episode.success, False, np)
    # episode_init hands one array as both coverage and best_coverage; written in place below, each needs its own
    # (shared, the final coverage read back was the best one: a T pushed past its best ended reporting its best)
    ep["best_coverage"] = ep["best_coverage"].copy()
    finite, contained = np.isfinite(state).all(-1), _inside(envs)
    states = [state.copy()] if trace else None
    for k in range(episode.max_steps):
        # the controller sees what gym-pusht's reset/step returned, through the door a user's loop goes through
        # (task/gym_pusht_obs.py, as GymPushtPolicy): never pymunk's bodies, which are read for the rows alone
        batch = {f: np.stack([o[f] for o in seen]) for f in ("pixels", "agent_pos")} if image else np.stack(seen)
        obs = controller_obs(batch, obs_type) | ({} if goal is None else {"goal": goal})
        action, carry = controller.act(carry, obs, k, key)
        bad = live & ~np.isfinite(np.asarray(action, np.float64)).all(-1)
        if bad.any():  # the controller's bug, said as the other backends say it: never a pusher quietly held still
            from mjx_pusht.task.controllers import ControllerError

            raise ControllerError(f"controller {controller.name} gave a non-finite action at step {k} for seeds "
                                  f"{seeds[bad][:8].tolist()}")
        target = gym_pusht_action(action)
        for i in np.flatnonzero(live):
            seen[i], _, terminated, _, info = envs[i].step(target[i])
            state[i] = world_state(envs[i])
            cov = float(info["coverage"])
            ep["length"][i] = k + 1
            ep["return"][i] += cov  # the task's reward, coverage (gym-pusht's own is clip(coverage / threshold))
            ep["coverage"][i], ep["best_coverage"][i] = cov, max(ep["best_coverage"][i], cov)
            if info["is_success"] and not ep["success"][i]:
                ep["success"][i], ep["steps_to_success"][i] = True, k + 1
            if terminated:
                ep["done"][i], live[i] = True, False
        finite &= np.isfinite(state).all(-1)
        contained &= _inside(envs)
        if trace:
            states.append(state.copy())
        if not live.any() and not trace:
            break
    for e in envs:
        e.close()
    rows = Rollouts(seeds=seeds, start=start, settled=start.copy(), final=state[:, 2:5].copy(),
                    pusher_final=state[:, 0:2].copy(), gap_settled=np.full(n, GAP), gap_max_dev=np.zeros(n),
                    finite=finite, contained=contained, pusher_start=pusher_start,
                    episode=ep if goal is None else {**ep, "goal": goal})
    return rows, (np.stack(states, axis=1) if trace else None)


def _inside(envs) -> np.ndarray:
    """Agent and block inside gym-pusht's 512-pixel window (a body past it went through a wall)."""
    return np.array([all(0 <= v <= 512 for v in (*e.agent.position, *e.block.position)) for e in envs])
