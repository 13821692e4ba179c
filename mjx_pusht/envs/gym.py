"""PushT for gymnasium: `mjx_pusht/PushT-v0` (one env, MuJoCo C) and its vector entry point (the batch).

    import gymnasium as gym, mjx_pusht
    env = gym.make("mjx_pusht/PushT-v0", obs_type="pixels_agent_pos")
    envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=4096, backend="auto")

Both are thin shells over `env.PushTEnv`, the functional environment every backend runs, so a
vector env of N steps all N worlds in one batch (one compiled program on MJX; MuJoCo C on
`threads` threads otherwise), never N copies in subprocesses (envs/vector.py).

Where this differs from gym-pusht (and how to convert):
- units are metres and radians in the world frame, the target T at the origin with yaw 0;
  `task.to_pixels(xy)` / `task.from_pixels(px)` convert positions to and from gym-pusht's
  512-pixel frame (which is also the frame of the pixel observations, at any size);
- the pusher is on velocity servos: `action_type="velocity"` (default) commands m/s in
  [-1, 1]; `action_type="position"` takes a target (x, y) in metres, tracked by a
  proportional velocity command (task.to_ctrl), gym-pusht's convention; actions are clipped
  to the action space, and a NaN or inf is a one-line error;
- reward is the coverage itself, in [0, 1] (gym-pusht: coverage / 0.95, clipped); success
  (terminated) at coverage >= 0.95 (`success_threshold=`: another, in (0, 1]); a start already on the
  goal is over at reset (info says success), its first step terminated with that start's coverage as reward;
  truncation after `max_episode_steps` control steps (300, registered in the spec: gymnasium's
  TimeLimit truncates, so `gym.make(..., max_episode_steps=500)` runs 500);
- observations: `state` = [pusher x, y, tee x, y, yaw in (-pi, pi]], `keypoints` = the T's 8
  outline corners (16 values), `pixels` = (96, 96, 3) uint8, `pixels_agent_pos` = {pixels,
  agent_pos}; `goal="random"`: a goal pose per episode from its seed (task/goals.py), its (x, y, yaw)
  after the state and its T's 16 keypoints after the T's, `info["goal_pose"]`, reward and success toward
  it; `options={"reset_to_state": [tee x, y, yaw, pusher x, y]}` starts from a given
  state (the order `reset.start_poses` uses); reset options this env does not use are ignored;
- `randomize={"tee_mass": (0.5, 2.0), "kv": (0.8, 1.2)}` draws each episode's physics from its seed (scale
  factors on the task's own values, model/randomize.py: the same draw as `eval --randomize` for that seed);
  info["physics"] = {name: value} holds the drawn values (kg, gains). Nothing asked for: no such key.

The single env runs on NumPy and MuJoCo C only (no JAX), so it can be forked.
"""

from __future__ import annotations

import math

import numpy as np

from mjx_pusht.task import goals
from mjx_pusht.errors import requires

with requires("the gymnasium environments", "gym"):  # the extra is optional: say what to install, in one line
    import gymnasium as gym

from mjx_pusht import validate
from mjx_pusht.api import keywords
from mjx_pusht.envs import physics
from mjx_pusht.envs.common import (
    OneWorld,
    Pictures,
    action_bounds,
    check_kwargs,
    check_starts,
    functional,
    single_spaces,
    warn_broken,
)
from mjx_pusht.task.goals import with_goal
from mjx_pusht.render.pixels import IMAGE_SIZE
from mjx_pusht.envs.vector import PushTVectorEnv  # noqa: F401  (the vector entry point's historical home)
from mjx_pusht.task.reset import SEED_MAX

ENV_ID = "mjx_pusht/PushT-v0"
DROP_IN_ID = "mjx_pusht/PushT-gym-pusht-v0"
MAX_EPISODE_STEPS = 300  # both ids' registered limit, as gym-pusht registers its env


def one_action(state, action, shape_what: str, low, high) -> tuple[float, float]:
    """A single env's action as two floats (after reset), checked and clipped by the one validation layer."""
    validate.started(state)
    return validate.action_pair(action, low, high, shape_what)


def wrap_yaw(a: float) -> float:
    """`rules.wrap_angle` of one float: the same operations (Python's float % is NumPy's remainder), no arrays."""
    w = (a + math.pi) % (2 * math.pi) - math.pi
    return math.pi if w == -math.pi else w


class PushTGymEnv(OneWorld, Pictures, gym.Env):
    """One PushT episode at a time on MuJoCo C, float64 (the determinism reference).

    `max_episode_steps`: None (the default, and what `gym.make` passes) leaves truncation to gymnasium's
    TimeLimit, which the registration sets to 300; an integer makes the env truncate on its own."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    @keywords  # an unknown keyword: one line naming the known ones
    def __init__(self, obs_type: str = "state", action_type: str = "velocity", render_mode: str | None = None,
                 observation_size: int = IMAGE_SIZE, render_size: int = 512, reset_kind: str = "task",
                 max_episode_steps: int | None = None, frame_skip: int = 10,
                 success_threshold: float | None = None, goal: str = "fixed", randomize=None):
        check_kwargs(obs_type, action_type, observation_size)
        self.render_mode = validate.render_mode(render_mode, human=True)
        self.obs_type, self.action_type = obs_type, action_type
        self.render_size = validate.image_size(render_size, "render_size")
        self._env = functional("cpu", obs_type, action_type, observation_size, reset_kind,
                               validate.episode_limit(max_episode_steps), frame_skip,
                               success_threshold=success_threshold, goal=goal, randomize=randomize)
        self.observation_space, self.action_space = single_spaces(obs_type, action_type, observation_size, np.float64,
                                                                  goals.check(goal) != "fixed")
        self._low, self._high = action_bounds(action_type)
        self.metadata = {**self.metadata, "render_fps": self._fps}
        self._state = None
        self._open_window()

    @keywords  # (not step: the hot path, where gymnasium's wrappers meet a stray keyword first)
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        seed = validate.seed(seed)
        options = validate.reset_options(options, ("reset_to_state",), type(self).__name__)
        super().reset(seed=seed)
        if "reset_to_state" in options:
            start = check_starts(options["reset_to_state"], 1)
            self._state = self._env.reset_to(start, [0 if seed is None else seed])
        else:
            # a given seed is the functional API's seed (same start pose); later resets draw the next
            # seed from the env's own generator, as gymnasium envs do
            episode_seed = seed if seed is not None else int(self.np_random.integers(SEED_MAX))
            self._state = self._env.reset([episode_seed])
        if self.render_mode == "human":
            self.render()
        return self._obs(), self._info()

    def step(self, action):
        x, y = one_action(self._state, action, "(x, y) pair", self._low, self._high)
        self._state = s = self._step_world(x, y)  # (x, y) is checked and clipped
        if self.render_mode == "human":
            self.render()
        return self._obs(), float(s.reward[0]), bool(s.terminated[0]), bool(s.truncated[0]), self._info()

    def _obs(self):
        o, t = self._state.obs, self.obs_type
        s = o["state"][0]
        if t == "state":
            px, py, tx, ty, yaw = s.tolist()
            out = np.array([px, py, tx, ty, wrap_yaw(yaw)])
            return out if "goal" not in o else with_goal(out, o["goal"][0], t)
        if t == "keypoints":
            return o["keypoints"][0].copy() if "goal" not in o else with_goal(o["keypoints"][0], o["goal"][0], t)
        if t == "pixels":
            return o["pixels"][0]
        return {"pixels": o["pixels"][0], "agent_pos": s[0:2].copy()}

    def _info(self) -> dict:
        s = self._state
        m, st = s.metrics, s.obs["state"][0]
        info = {
            "coverage": m["coverage"][0],
            "is_success": s.terminated[0],
            "steps": np.int64(s.step[0]),
            "block_pose": st[2:5].copy(),
            "pos_agent": st[0:2].copy(),
            "weld_gap_max_dev": m["gap_max_dev"][0],
            "finite": m["finite"][0],  # every state of the episode finite and bounded
            "contained": m["contained"][0],  # the block and the pusher never left the walls (no missed contact)
        }
        if "goal" in s.obs:  # a random goal's pose (a fixed one is the origin)
            info["goal_pose"] = s.obs["goal"][0].copy()
        if not (info["finite"] and info["contained"]):
            warn_broken(info)
        return info | physics.info(self._env, None if s.physics is None else s.physics[0])

    @keywords
    def render(self):
        """rgb_array: the picture; human: shown in the window (None); no render_mode: None."""
        if self.render_mode is None:
            return None
        validate.started(self._state, "render")
        return self._shown(self._draw(self._state.data.qpos[-1], self._state.carry.get("goal"))[0])

    def close(self):
        self._close_renderers()


def register() -> None:
    """Register `mjx_pusht/PushT-v0` and the gym-pusht drop-in `mjx_pusht/PushT-gym-pusht-v0` with gymnasium
    (done on `import mjx_pusht` when gymnasium is installed). Both are registered as gym-pusht registers
    its env: gymnasium's TimeLimit at 300 steps, which `max_episode_steps=` replaces (the vector entry
    points take it as their own limit)."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="mjx_pusht.envs.gym:PushTGymEnv",
                     vector_entry_point="mjx_pusht.envs.vector:PushTVectorEnv", max_episode_steps=MAX_EPISODE_STEPS)
    if DROP_IN_ID not in gym.registry:
        gym.register(id=DROP_IN_ID, entry_point="mjx_pusht.envs.gym_pusht:GymPushTEnv",
                     vector_entry_point="mjx_pusht.envs.gym_pusht:GymPushTVectorEnv",
                     max_episode_steps=MAX_EPISODE_STEPS, kwargs={"obs_type": "state"})
