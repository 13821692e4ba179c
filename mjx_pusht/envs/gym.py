"""PushT for gymnasium: `mjx_pusht/PushT-v0` (one env, MuJoCo C) and its vector entry point (the batch).

    import gymnasium as gym, mjx_pusht
    env = gym.make("mjx_pusht/PushT-v0", obs_type="pixels_agent_pos")
    envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=4096, backend="auto")

Both are thin shells over `env.PushTEnv`, the functional environment every backend runs, so a
vector env of N steps all N worlds in one batch (one compiled program on MJX; MuJoCo C on
`threads` threads otherwise), never N copies in subprocesses.

Where this differs from gym-pusht (and how to convert):
- units are metres and radians in the world frame, the target T at the origin with yaw 0;
  `task.to_pixels(xy)` / `task.from_pixels(px)` convert positions to and from gym-pusht's
  512-pixel frame (which is also the frame of the pixel observations, at any size);
- the pusher is on velocity servos: `action_type="velocity"` (default) commands m/s in
  [-1, 1]; `action_type="position"` takes a target (x, y) in metres, tracked by a
  proportional velocity command (task.to_ctrl), gym-pusht's convention;
- reward is the coverage itself, in [0, 1] (gym-pusht: coverage / 0.95, clipped); success
  (terminated) at coverage >= 0.95, truncation after `max_episode_steps` control steps (300);
- observations: `state` = [pusher x, y, tee x, y, yaw in (-pi, pi]], `keypoints` = the T's 8
  outline corners (16 values), `pixels` = (96, 96, 3) uint8, `pixels_agent_pos` = {pixels,
  agent_pos}; `options={"reset_to_state": [tee x, y, yaw, pusher x, y]}` starts from a given
  state (the order `reset.start_poses` uses).
"""

from __future__ import annotations

import math

import numpy as np

try:
    import gymnasium as gym
    from gymnasium import spaces
    from gymnasium.vector import AutoresetMode, VectorEnv
    from gymnasium.vector.utils import batch_space
except ImportError as e:  # the extra is optional: say what to install, in one line
    raise ImportError("the gymnasium environments need gymnasium: pip install 'mjx-pusht[gym]'") from e

from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.pixels import IMAGE_SIZE
from mjx_pusht.errors import ConfigError
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.reset import SEED_MAX
from mjx_pusht.task.rules import ACTION_TYPES, CTRL_LIMIT, WORKSPACE_HALF, wrap_angle

OBS_TYPES = ("state", "keypoints", "pixels", "pixels_agent_pos")
TABLE_HALF = 0.45  # every position in an observation lies on the table (the walls stop the bodies sooner)
ENV_ID = "mjx_pusht/PushT-v0"


def _check(obs_type: str, action_type: str) -> None:
    if obs_type not in OBS_TYPES:
        raise ConfigError(f"unknown obs_type {obs_type!r}; choose from {', '.join(OBS_TYPES)}")
    if action_type not in ACTION_TYPES:
        raise ConfigError(f"unknown action_type {action_type!r}; choose from {', '.join(ACTION_TYPES)}")


def single_spaces(obs_type: str, action_type: str, size: int, dtype) -> tuple[spaces.Space, spaces.Box]:
    """The observation and action space of one environment."""
    img = spaces.Box(0, 255, (size, size, 3), np.uint8)
    agent = spaces.Box(-TABLE_HALF, TABLE_HALF, (2,), dtype)
    if obs_type == "state":
        hi = np.array([TABLE_HALF] * 4 + [math.pi])
        obs = spaces.Box(-hi, hi, (5,), dtype)
    elif obs_type == "keypoints":
        obs = spaces.Box(-TABLE_HALF, TABLE_HALF, (16,), dtype)
    elif obs_type == "pixels":
        obs = img
    else:
        obs = spaces.Dict({"pixels": img, "agent_pos": agent})
    limit = CTRL_LIMIT if action_type == "velocity" else WORKSPACE_HALF
    return obs, spaces.Box(-limit, limit, (2,), np.float32)


def _gym_obs(obs: dict, obs_type: str, dtype):
    """The functional env's observation dict as a gymnasium observation (batched or not)."""
    if obs_type == "state":
        s = np.asarray(obs["state"], dtype).copy()
        s[..., 4] = wrap_angle(s[..., 4])
        return s
    if obs_type == "keypoints":
        return np.asarray(obs["keypoints"], dtype)
    pixels = np.asarray(obs["pixels"], np.uint8)
    if obs_type == "pixels":
        return pixels
    return {"pixels": pixels, "agent_pos": np.asarray(obs["state"][..., 0:2], dtype)}


def _host(state, obs_type: str) -> dict:
    """What a gymnasium step hands out, copied to the host in one transfer (a no-op for NumPy states)."""
    import jax

    keys = {"state"} | ({"keypoints"} if obs_type == "keypoints" else set()) | (
        {"pixels"} if obs_type.startswith("pixels") else set())
    m = state.metrics
    return jax.device_get({"obs": {k: state.obs[k] for k in keys}, "reward": state.reward,
                           "terminated": state.terminated, "truncated": state.truncated, "step": state.step,
                           "coverage": m["coverage"], "gap_max_dev": m["gap_max_dev"], "finite": m["finite"],
                           "contained": m["contained"]})


def _infos(h: dict) -> dict:
    """coverage, is_success and the rest, per world, from a `_host` copy."""
    s = np.asarray(h["obs"]["state"])
    return {
        "coverage": np.asarray(h["coverage"], np.float64),
        "is_success": np.asarray(h["terminated"], bool),
        "steps": np.asarray(h["step"], np.int64),
        "block_pose": np.asarray(s[..., 2:5], np.float64),
        "pos_agent": np.asarray(s[..., 0:2], np.float64),
        "weld_gap_max_dev": np.asarray(h["gap_max_dev"], np.float64),
        "finite": np.asarray(h["finite"], bool),  # every state of the episode finite and bounded
        "contained": np.asarray(h["contained"], bool),  # the block never left the walls (no missed contact)
    }


def _warn_broken(info: dict) -> None:
    """A diverged or escaped world is physics gone wrong: say so, never just hand its numbers on."""
    bad = ~(info["finite"] & info["contained"])
    if np.any(bad):
        import warnings

        warnings.warn(f"mjx_pusht: {int(np.sum(bad))} environment(s) went non-finite or left the walls "
                      "(info['finite'], info['contained'] are False): their observations are not physics",
                      RuntimeWarning, stacklevel=3)


def _functional(backend: str, obs_type: str, action_type: str, observation_size: int, reset_kind: str,
                max_episode_steps: int, frame_skip: int, threads: int = 1) -> PushTEnv:
    """The functional env behind both gymnasium envs; stepped in place (a gymnasium env keeps no old states)."""
    return PushTEnv(backend=backend, reset_kind=reset_kind, action_type=action_type,
                    pixels=observation_size if obs_type.startswith("pixels") else 0,
                    episode=Episode(frame_skip=frame_skip, max_steps=max_episode_steps), threads=threads,
                    keep_states=False)


class _Pictures:
    """rgb_array pictures for both envs (the CPU renderer at `render_size`), and closing what renders."""

    _viewer = None

    def _draw(self, qpos) -> np.ndarray:
        if self._viewer is None:
            from mjx_pusht.envs.pixels import CpuRenderer

            self._viewer = CpuRenderer(self._env.model, self.render_size)
        return self._viewer(np.asarray(qpos, np.float64))

    def _close_renderers(self) -> None:
        for r in (self._viewer, getattr(self._env, "renderer", None)):
            if r is not None:
                r.close()
        self._viewer = None

    @property
    def _fps(self) -> int:
        return round(1 / (self._env.episode.frame_skip * self._env.model.opt.timestep))


class PushTGymEnv(_Pictures, gym.Env):
    """One PushT episode at a time on MuJoCo C, float64 (the determinism reference)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, obs_type: str = "state", action_type: str = "velocity", render_mode: str | None = None,
                 observation_size: int = IMAGE_SIZE, render_size: int = 512, reset_kind: str = "task",
                 max_episode_steps: int = 300, frame_skip: int = 10):
        _check(obs_type, action_type)
        if render_mode not in (None, "rgb_array"):
            raise ConfigError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.obs_type, self.action_type, self.render_mode = obs_type, action_type, render_mode
        self.render_size = render_size
        self._env = _functional("cpu", obs_type, action_type, observation_size, reset_kind, max_episode_steps,
                                frame_skip)
        self.observation_space, self.action_space = single_spaces(obs_type, action_type, observation_size, np.float64)
        self.metadata = {**self.metadata, "render_fps": self._fps}
        self._state = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = options or {}
        if "reset_to_state" in options:
            start = np.asarray(options["reset_to_state"], np.float64).reshape(1, -1)
            self._state = self._env.reset_to(start, [0 if seed is None else seed])
        else:
            # a given seed is the functional API's seed (same start pose); later resets draw the next
            # seed from the env's own generator, as gymnasium envs do
            episode_seed = seed if seed is not None else int(self.np_random.integers(SEED_MAX))
            self._state = self._env.reset([episode_seed])
        return self._obs(), self._info()

    def step(self, action):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        action = np.asarray(action, np.float64)
        if action.shape != (2,):
            raise ConfigError(f"an action is one (x, y) pair, shape (2,); got shape {action.shape}")
        self._state = self._env.step(self._state, action[None])
        s = self._state
        return self._obs(), float(s.reward[0]), bool(s.terminated[0]), bool(s.truncated[0]), self._info()

    def _obs(self):
        return _gym_obs({k: v[0] for k, v in self._state.obs.items()}, self.obs_type, np.float64)

    def _info(self) -> dict:
        info = {k: v[0] for k, v in _infos(_host(self._state, self.obs_type)).items()}
        _warn_broken(info)
        return info

    def render(self):
        return self._draw(self._state.data.qpos[-1])[0] if self.render_mode == "rgb_array" else None

    def close(self):
        self._close_renderers()


class PushTVectorEnv(_Pictures, VectorEnv):
    """N PushT episodes stepped as one batch on any backend (`auto`: MJX-Warp on a GPU, else MuJoCo C).

    Autoreset follows gymnasium's modes: `next_step` (the default: the step after an episode
    ends resets it and ignores its action), `same_step` (reset at once; the ended episode's
    observation and info go in info["final_obs"] / info["final_info"]) or `disabled`
    (reset(options={"reset_mask": mask}) resets the ones you pick).
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, backend: str = "auto", obs_type: str = "state",
                 action_type: str = "velocity", render_mode: str | None = None, observation_size: int = IMAGE_SIZE,
                 render_size: int = 512, reset_kind: str = "task", max_episode_steps: int = 300,
                 frame_skip: int = 10, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 threads: int | None = None):
        from mjx_pusht.backends.base import resolve
        from mjx_pusht.backends.cpu import default_threads

        _check(obs_type, action_type)
        if int(num_envs) < 1:
            raise ConfigError(f"num_envs must be a positive integer, got {num_envs}")
        self.num_envs = int(num_envs)
        self.backend, _ = resolve(backend)
        self.obs_type, self.action_type, self.render_mode = obs_type, action_type, render_mode
        # by enum, by value ("SameStep"), by name ("SAME_STEP") or in snake case ("same_step")
        names = {k: m for m in AutoresetMode for k in (m, m.value, m.name, m.name.lower())}
        if autoreset_mode not in names:
            raise ConfigError(f"unknown autoreset_mode {autoreset_mode!r}; choose from "
                              f"{', '.join(m.name.lower() for m in AutoresetMode)}")
        self.autoreset_mode = names[autoreset_mode]
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.render_size = render_size
        threads = threads or (min(default_threads(), max(1, self.num_envs // 64)) if self.backend == "cpu" else 1)
        self._env = _functional(self.backend, obs_type, action_type, observation_size, reset_kind,
                                max_episode_steps, frame_skip, threads)
        self._dtype = np.float64 if self.backend == "cpu" else np.dtype(self._env.runner.dtype)
        self.single_observation_space, self.single_action_space = single_spaces(
            obs_type, action_type, observation_size, self._dtype)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata["render_fps"] = self._fps
        self._rngs = [np.random.default_rng() for _ in range(self.num_envs)]
        self._state = None
        self._needs_reset = np.zeros(self.num_envs, bool)
        self._viewer = None

    # Each sub-environment draws its next episode seed from its own generator, seeded like
    # gymnasium's SyncVectorEnv seeds its copies (seed + i), so this batch and N single envs agree.
    def _next_seeds(self, rows) -> np.ndarray:
        return np.array([int(self._rngs[i].integers(SEED_MAX)) for i in rows], np.int64)

    def reset(self, *, seed=None, options: dict | None = None):
        options = options or {}
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else list(seed)
            if len(seeds) != self.num_envs:
                raise ConfigError(f"{len(seeds)} seeds for {self.num_envs} environments")
        else:
            seeds = [None] * self.num_envs
        mask = np.asarray(options.get("reset_mask", np.ones(self.num_envs, bool)), bool)
        if mask.shape != (self.num_envs,):
            raise ConfigError(f"reset_mask must be ({self.num_envs},) booleans, got shape {mask.shape}")
        rows = np.flatnonzero(mask)
        for i in rows:
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng(seeds[i])
        episode_seeds = np.array([seeds[i] if seeds[i] is not None else int(self._rngs[i].integers(SEED_MAX))
                                  for i in rows], np.int64)
        starts = options.get("reset_to_state")
        if starts is not None:
            starts = np.broadcast_to(np.asarray(starts, np.float64), (len(rows), 5))
        if self._state is None or mask.all():
            if starts is not None:
                self._state = self._env.reset_to(starts, episode_seeds)
            else:
                self._state = self._env.reset(episode_seeds)
        else:
            self._state = self._env.reset_where(self._state, mask, episode_seeds, starts)
        self._needs_reset[rows] = False
        self._fetch()
        return self._obs(), self._info()

    def step(self, actions):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        actions = np.asarray(actions, np.float64)
        if actions.shape != (self.num_envs, 2):
            raise ConfigError(f"actions must have shape ({self.num_envs}, 2), one (x, y) per environment; "
                              f"got {actions.shape} (never reshaped: that would scramble the environments)")
        self._state = self._env.check(self._env.step(self._state, actions))
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._needs_reset.any():
            # the episodes that ended last step start again now; this step's action is not theirs
            rows = np.flatnonzero(self._needs_reset)
            self._state = self._env.reset_where(self._state, self._needs_reset, self._next_seeds(rows))
        h = self._fetch()
        terminated, truncated = np.array(h["terminated"], bool), np.array(h["truncated"], bool)
        reward = np.array(h["reward"], np.float64)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            reset_rows = self._needs_reset
            terminated[reset_rows], truncated[reset_rows], reward[reset_rows] = False, False, 0.0
            self._needs_reset = terminated | truncated
            return self._obs(), reward, terminated, truncated, self._info()
        obs, info = self._obs(), self._info()
        ended = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP and ended.any():
            rows = np.flatnonzero(ended)
            final_obs, final_info = obs, info
            self._state = self._env.reset_where(self._state, ended, self._next_seeds(rows))
            self._fetch()
            obs, info = self._obs(), self._info()
            info = {**info, "final_obs": final_obs, "final_info": final_info, "_final_obs": ended,
                    "_final_info": ended}
        return obs, reward, terminated, truncated, info

    def _fetch(self) -> dict:
        self._h = _host(self._state, self.obs_type)
        return self._h

    def _obs(self):
        return _gym_obs(self._h["obs"], self.obs_type, self._dtype)

    def _info(self) -> dict:
        info = _infos(self._h)
        _warn_broken(info)
        every = np.ones(self.num_envs, bool)
        return info | {f"_{k}": every for k in info}

    def render(self):
        """One picture per environment, as a tuple (gymnasium's convention), drawn on the CPU renderer:
        about 4 ms each at 512 x 512 on this project's 2-core machine, so mind it for thousands of envs."""
        if self.render_mode != "rgb_array":
            return None
        return tuple(self._draw(self._state.data.qpos[-1] if self.backend == "cpu" else self._state.data.qpos))

    def close_extras(self, **kwargs):
        self._close_renderers()

    # gymnasium's vector API, as SyncVectorEnv offers it: one batch, so an attribute is the same for every env
    def call(self, name: str, *args, **kwargs) -> tuple:
        """`name` called (or read, if not callable) on the env, once per sub-environment, as SyncVectorEnv does."""
        attr = self._env.episode.max_steps if name == "_max_episode_steps" else getattr(self, name)
        value = attr(*args, **kwargs) if callable(attr) else attr
        return (value,) * self.num_envs

    def get_attr(self, name: str) -> tuple:
        return self.call(name)

    def set_attr(self, name: str, values) -> None:
        values = values if isinstance(values, (list, tuple)) else [values] * self.num_envs
        if len(values) != self.num_envs or any(v != values[0] for v in values[1:]):
            raise ConfigError(f"the {self.num_envs} environments are one batch: set_attr needs one value for all")
        setattr(self, name, values[0])


def register() -> None:
    """Register `mjx_pusht/PushT-v0` with gymnasium (done on `import mjx_pusht` when gymnasium is installed)."""
    if ENV_ID in gym.registry:
        return
    gym.register(id=ENV_ID, entry_point="mjx_pusht.envs.gym:PushTGymEnv",
                 vector_entry_point="mjx_pusht.envs.gym:PushTVectorEnv", max_episode_steps=None)
