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
from mjx_pusht.envs.handoff import check_array_type, from_user, hand_off
from mjx_pusht.render.pixels import IMAGE_SIZE
from mjx_pusht.errors import ConfigError
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.reset import SEED_MAX
from mjx_pusht.task.rules import ACTION_TYPES, CTRL_LIMIT, WORKSPACE_HALF, wrap_angle

OBS_TYPES = ("state", "keypoints", "pixels", "pixels_agent_pos")
TABLE_HALF = 0.45  # every position in an observation lies on the table (the walls stop the bodies sooner)
ENV_ID = "mjx_pusht/PushT-v0"


def _check(obs_type: str, action_type: str, observation_size: int = IMAGE_SIZE) -> None:
    if obs_type.startswith("pixels"):
        from mjx_pusht.render.pixels import _check_size

        _check_size(observation_size)
    if obs_type not in OBS_TYPES:
        raise ConfigError(f"unknown obs_type {obs_type!r}; choose from {', '.join(OBS_TYPES)}")
    if action_type not in ACTION_TYPES:
        raise ConfigError(f"unknown action_type {action_type!r}; choose from {', '.join(ACTION_TYPES)}")


def _check_seed(seed) -> None:
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                             or not 0 <= int(seed) <= SEED_MAX):
        raise ConfigError(f"a seed is an integer from 0 to 2**63-1, got {seed!r}")


def _check_options(options: dict, allowed: tuple) -> dict:
    unknown = set(options) - set(allowed)
    if unknown:
        raise ConfigError(f"unknown reset option(s) {', '.join(map(repr, sorted(unknown)))}; "
                          f"the options are {', '.join(allowed)}")
    return options


def _check_starts(starts, rows: int) -> np.ndarray:
    """reset_to_state: [tee x, y, yaw, pusher x, y] for every reset env (or one for all), finite."""
    a = np.asarray(starts, np.float64)
    if a.shape not in ((5,), (rows, 5)):
        raise ConfigError(f"reset_to_state is [tee x, y, yaw, pusher x, y]: shape (5,) or ({rows}, 5), got {a.shape}")
    if not np.isfinite(a).all():
        raise ConfigError("reset_to_state must be finite numbers")
    return np.broadcast_to(a, (rows, 5))


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


_METRICS = ("coverage", "gap_max_dev", "finite", "contained")


def _jnp():
    import jax.numpy as jnp

    return jnp


def _warn_broken(info: dict) -> None:
    """A diverged or escaped world is physics gone wrong: say so, never just hand its numbers on."""
    bad = ~(np.asarray(info["finite"], bool) & np.asarray(info["contained"], bool))
    if np.any(bad):
        import warnings

        warnings.warn(f"mjx_pusht: {int(np.sum(bad))} environment(s) went non-finite or left the walls "
                      "(info['finite'], info['contained'] are False): their observations are not physics",
                      RuntimeWarning, stacklevel=3)


def _functional(backend: str, obs_type: str, action_type: str, observation_size: int, reset_kind: str,
                max_episode_steps: int, frame_skip: int, threads: int = 1, variant: str = "chapter") -> PushTEnv:
    """The functional env behind the gymnasium envs; stepped in place (a gymnasium env keeps no old states).
    The gym-pusht variant's episodes run as gym-pusht's do: a start on the goal is scored by the first step."""
    from mjx_pusht.model.scene import SceneSpec

    return PushTEnv(backend=backend, reset_kind=reset_kind, action_type=action_type,
                    pixels=observation_size if obs_type.startswith("pixels") else 0,
                    episode=Episode(frame_skip=frame_skip, max_steps=max_episode_steps,
                                    end_covered_start=variant == "chapter"),
                    scene=SceneSpec(variant=variant), threads=threads, keep_states=False)


class _Pictures:
    """rgb_array pictures for both envs (the CPU renderer at `render_size`), and closing what renders."""

    _viewer = None

    def _draw(self, qpos) -> np.ndarray:
        if self._viewer is None:
            from mjx_pusht.render.pixels import CpuRenderer

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


def one_action(state, action, what: str) -> np.ndarray:
    """A single env's action as (2,) float64 (after reset): a wrong shape is a one-line error, never reshaped."""
    if state is None:
        raise RuntimeError("call reset() before step()")
    a = np.asarray(action, np.float64)
    if a.shape != (2,):
        raise ConfigError(f"an action is one (x, y) {what}, shape (2,); got shape {a.shape}")
    return a


class PushTGymEnv(_Pictures, gym.Env):
    """One PushT episode at a time on MuJoCo C, float64 (the determinism reference)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, obs_type: str = "state", action_type: str = "velocity", render_mode: str | None = None,
                 observation_size: int = IMAGE_SIZE, render_size: int = 512, reset_kind: str = "task",
                 max_episode_steps: int = 300, frame_skip: int = 10):
        _check(obs_type, action_type, observation_size)
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
        _check_seed(seed)
        options = _check_options(options or {}, ("reset_to_state",))
        super().reset(seed=seed)
        if "reset_to_state" in options:
            start = _check_starts(options["reset_to_state"], 1)
            self._state = self._env.reset_to(start, [0 if seed is None else seed])
        else:
            # a given seed is the functional API's seed (same start pose); later resets draw the next
            # seed from the env's own generator, as gymnasium envs do
            episode_seed = seed if seed is not None else int(self.np_random.integers(SEED_MAX))
            self._state = self._env.reset([episode_seed])
        return self._obs(), self._info()

    def step(self, action):
        action = one_action(self._state, action, "pair")
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
    (reset(options={"reset_mask": mask}) resets the ones you pick). On MJX the autoreset runs
    on the device inside the jitted step (wrappers.AutoReset), from start poses drawn ahead
    by each env's own generator, so the episodes are those of gymnasium's SyncVectorEnv.

    `array_type`: what observations, rewards, flags and infos come out as: "jax" (the default
    on MJX: arrays on the device, no copy), "torch" (tensors on the same device through DLPack,
    no copy) or "numpy" (copied to the host; the only choice on cpu). Actions may be any of
    the three. Physics gone wrong is checked on the device and raised or warned about at least
    every `depth` // 2 steps (every step with NumPy output): a dropped contact (BufferOverflow),
    a non-finite or escaped world (RuntimeWarning).
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, backend: str = "auto", obs_type: str = "state",
                 action_type: str = "velocity", render_mode: str | None = None, observation_size: int = IMAGE_SIZE,
                 render_size: int = 512, reset_kind: str = "task", max_episode_steps: int = 300,
                 frame_skip: int = 10, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 threads: int | None = None, array_type: str | None = None, depth: int = 8,
                 variant: str = "chapter"):
        from mjx_pusht.backends.base import resolve
        from mjx_pusht.backends.cpu import default_threads
        from mjx_pusht.envs.wrappers import AutoReset, StartPool

        self._check_args(obs_type, action_type, observation_size)
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ConfigError(f"num_envs must be a positive integer, got {num_envs!r}")
        self.num_envs = int(num_envs)
        self.backend, _ = resolve(backend)
        self.obs_type, self.action_type, self.render_mode = obs_type, action_type, render_mode
        # by enum, by value ("SameStep"), by name ("SAME_STEP") or in snake case ("same_step")
        names = {k: m for m in AutoresetMode for k in (m, m.value, m.name, m.name.lower())}
        if autoreset_mode not in names:
            raise ConfigError(f"unknown autoreset_mode {autoreset_mode!r}; choose from "
                              f"{', '.join(m.name.lower() for m in AutoresetMode)}")
        self.autoreset_mode = names[autoreset_mode]
        self.array_type = check_array_type(array_type or ("numpy" if self.backend == "cpu" else "jax"))
        if self.backend == "cpu" and self.array_type != "numpy":
            raise ConfigError("the cpu backend steps MuJoCo C on the host: its arrays are NumPy (array_type='numpy')")
        self.metadata = {**self.metadata, "autoreset_mode": self.autoreset_mode}
        self.render_size = render_size
        threads = threads or (min(default_threads(), max(1, self.num_envs // 64)) if self.backend == "cpu" else 1)
        self._env = _functional(self.backend, obs_type, action_type, observation_size, reset_kind,
                                max_episode_steps, frame_skip, threads, variant)
        self._dtype = np.float64 if self.backend == "cpu" else np.dtype(self._env.runner.dtype)
        self.single_observation_space, self.single_action_space = self._single_spaces(
            obs_type, action_type, observation_size, self._dtype)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata["render_fps"] = self._fps
        # each env's next episode seeds, from its own generator, seeded as SyncVectorEnv seeds its copies
        # (seed + i), so this batch and N single envs agree
        self._pool = StartPool(self._env, self.num_envs, depth)
        self._ar = None
        if self.backend != "cpu" and self.autoreset_mode != AutoresetMode.DISABLED:
            mode = "same_step" if self.autoreset_mode == AutoresetMode.SAME_STEP else "next_step"
            self._ar = AutoReset(self._env, mode, depth, final_pixels=obs_type.startswith("pixels"))
            self._ar.pool = self._pool
        self._state = None
        self._needs_reset = np.zeros(self.num_envs, bool)
        self._since_check = 0
        self._viewer = self._view_jit = None

    _check_args = staticmethod(_check)
    _single_spaces = staticmethod(single_spaces)
    _starts_in = staticmethod(_check_starts)  # reset_to_state, in the env's units

    def _actions_in(self, actions):
        """Actions in the functional env's units (this env's are those already)."""
        return actions

    def reset(self, *, seed=None, options: dict | None = None):
        options = dict(options or {})
        if seed is not None:
            seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, (int, np.integer)) else list(seed)
            if len(seeds) != self.num_envs:
                raise ConfigError(f"{len(seeds)} seeds for {self.num_envs} environments")
            for x in seeds:
                _check_seed(x)
        else:
            seeds = [None] * self.num_envs
        mask = np.asarray(options.pop("reset_mask", np.ones(self.num_envs, bool)), bool)
        if mask.shape != (self.num_envs,):
            raise ConfigError(f"reset_mask must be ({self.num_envs},) booleans, got shape {mask.shape}")
        starts = options.pop("reset_to_state", None)
        _check_options(options, ("reset_mask", "reset_to_state"))
        if self._state is None and not mask.all():
            raise ConfigError("the first reset starts every environment: reset_mask applies once they are running")
        rows = np.flatnonzero(mask)
        episode_seeds = self._episode_seeds(rows, [seeds[i] for i in rows])
        if starts is not None:
            starts = self._starts_in(starts, len(rows))
        if self._state is None or mask.all():
            if starts is not None:
                self._state = self._env.reset_to(starts, episode_seeds)
            else:
                self._state = self._env.reset(episode_seeds)
        else:
            self._state = self._env.reset_where(self._state, mask, episode_seeds, starts)
        if self._ar is not None:
            self._pool.refill(self._pool.used)
            self._state = self._ar._with_pool(self._state, self._pool.used)
        self._needs_reset[rows] = False
        self._since_check = 0
        return self._outputs(self._state, reset=True)

    def _episode_seeds(self, rows, given) -> np.ndarray:
        """The seed of each reset row's episode: the one given (its generator reseeded by it), else the
        row's next one, from the queue of seeds drawn ahead if there is one (so the sequence stays its own)."""
        pool = self._pool
        if self._ar is not None and self._state is not None:
            pool.used = np.asarray(self._state.info["used"], np.int64).copy()
        out = []
        for i, s in zip(rows, given):
            if s is not None:
                pool.restart([i], [s])
                out.append(int(s))
            elif pool.filled[i] > pool.used[i]:  # drawn ahead: take it, so the row's sequence is unchanged
                out.append(int(pool.seeds[pool.used[i] % pool.depth, i]))
                pool.used[i] += 1
            else:
                out.append(int(pool.next_seeds([i])[0]))
                pool.filled[i] = pool.used[i] = 0
        return np.array(out, np.int64)

    def step(self, actions):
        if self._state is None:
            raise RuntimeError("call reset() before step()")
        actions = from_user(actions)
        if getattr(actions, "shape", None) is None:
            actions = np.asarray(actions, np.float64)
        if tuple(actions.shape) != (self.num_envs, 2):
            raise ConfigError(f"actions must have shape ({self.num_envs}, 2), one (x, y) per environment; "
                              f"got {tuple(actions.shape)} (never reshaped: that would scramble the environments)")
        actions = self._actions_in(actions)
        if self._ar is not None:
            return self._step_device(actions)
        actions = np.asarray(actions, np.float64) if self.backend == "cpu" else actions
        self._state = self._env.check(self._env.step(self._state, actions))
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._needs_reset.any():
            # the episodes that ended last step start again now; this step's action is not theirs
            rows = np.flatnonzero(self._needs_reset)
            self._state = self._env.reset_where(self._state, self._needs_reset, self._pool.next_seeds(rows))
        obs, reward, terminated, truncated, info = self._outputs(self._state)
        terminated, truncated, reward = np.array(terminated), np.array(truncated), np.array(reward)
        if self.autoreset_mode == AutoresetMode.NEXT_STEP:
            reset_rows = self._needs_reset
            terminated[reset_rows], truncated[reset_rows], reward[reset_rows] = False, False, 0.0
            self._needs_reset = terminated | truncated
            return obs, reward, terminated, truncated, info
        ended = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP and ended.any():
            rows = np.flatnonzero(ended)
            final_obs, final_info = obs, info
            self._state = self._env.reset_where(self._state, ended, self._pool.next_seeds(rows))
            obs, _, _, _, info = self._outputs(self._state)
            info = {**info, "final_obs": final_obs, "final_info": final_info, "_final_obs": ended,
                    "_final_info": ended}
        return obs, reward, terminated, truncated, info

    def _step_device(self, actions):
        """MJX with autoreset: one jitted call; the host looks at the flags only every depth // 2 steps."""
        self._state = self._ar.step(self._state, actions)
        self._since_check += 1
        if self.array_type == "numpy" or self._since_check >= max(1, self._pool.depth // 2):
            self._since_check = 0
            self._state = self._ar.refill(self._env.check(self._state))
            _warn_broken({"finite": ~np.asarray(self._state.info["broken"]), "contained": True})
        out = self._outputs(self._state)
        if self._ar.mode == "same_step":
            final = self._state.info["final"]
            ended = self._state.terminated | self._state.truncated
            fs = {"obs": {**final["obs"], "state": final["obs"]["state"]}, "reward": self._state.reward,
                  "terminated": self._state.terminated, "truncated": self._state.truncated,
                  "step": final["step"], **{k: final["metrics"][k] for k in _METRICS}}
            f_obs, _, _, _, f_info = self._arrays(fs)
            out[4].update({"final_obs": f_obs, "final_info": f_info, "_final_obs": ended, "_final_info": ended})
        return out

    def _outputs(self, state, reset: bool = False):
        """obs, reward, terminated, truncated, info of `state`, as `array_type` (reset: obs, info)."""
        m = state.metrics
        flat = {"obs": state.obs, "reward": state.reward, "terminated": state.terminated,
                "truncated": state.truncated, "step": state.step, **{k: m[k] for k in _METRICS}}
        obs, reward, terminated, truncated, info = self._arrays(flat)
        if self.array_type == "numpy":
            _warn_broken(info)
        return (obs, info) if reset else (obs, reward, terminated, truncated, info)

    def _arrays(self, flat: dict):
        """The gymnasium view of a state's arrays, then handed off: on the device in one jitted call,
        copied to the host first for NumPy."""
        keys = {"state", "pusher_vel"} | ({"keypoints"} if self.obs_type == "keypoints" else set()) | (
            {"pixels"} if self.obs_type.startswith("pixels") else set())
        flat = {**flat, "obs": {k: v for k, v in flat["obs"].items() if k in keys}}
        if self.array_type == "numpy":
            return self._view(hand_off(flat, "numpy"), np)
        if self._view_jit is None:
            import jax

            self._view_jit = jax.jit(lambda f: self._view(f, _jnp()))
        out = self._view_jit(flat)
        return hand_off(out, "torch") if self.array_type == "torch" else out

    def _view(self, flat: dict, xp):
        o, s = flat["obs"], flat["obs"]["state"]
        if self.obs_type == "state":
            obs = xp.concatenate([s[..., :4], wrap_angle(s[..., 4:5])], axis=-1).astype(self._dtype)
        elif self.obs_type == "keypoints":
            obs = o["keypoints"].astype(self._dtype)
        elif self.obs_type == "pixels":
            obs = o["pixels"]
        else:
            obs = {"pixels": o["pixels"], "agent_pos": s[..., 0:2].astype(self._dtype)}
        every = xp.ones(self.num_envs, dtype=bool)
        info = {
            "coverage": flat["coverage"], "is_success": flat["terminated"], "steps": flat["step"],
            "block_pose": s[..., 2:5], "pos_agent": s[..., 0:2],
            "weld_gap_max_dev": flat["gap_max_dev"],
            "finite": flat["finite"],  # every state of the episode finite and bounded
            "contained": flat["contained"],  # the block never left the walls (no missed contact)
        }
        if xp is np:  # the host's convention, as the single env and SyncVectorEnv give them
            info = {k: np.asarray(v, np.float64 if np.asarray(v).dtype.kind == "f" else
                                  (bool if np.asarray(v).dtype == bool else np.int64)) for k, v in info.items()}
            out = (obs, np.asarray(flat["reward"], np.float64), np.asarray(flat["terminated"], bool),
                   np.asarray(flat["truncated"], bool))
        else:
            out = (obs, flat["reward"], flat["terminated"], flat["truncated"])
        return out + (info | {f"_{k}": every for k in info},)

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
    """Register `mjx_pusht/PushT-v0` and the gym-pusht drop-in `mjx_pusht/PushT-gym-pusht-v0` with gymnasium
    (done on `import mjx_pusht` when gymnasium is installed). The drop-in is registered as gym-pusht registers
    its env: gymnasium's TimeLimit at 300 steps, which `max_episode_steps=` replaces."""
    if ENV_ID not in gym.registry:
        gym.register(id=ENV_ID, entry_point="mjx_pusht.envs.gym:PushTGymEnv",
                     vector_entry_point="mjx_pusht.envs.gym:PushTVectorEnv", max_episode_steps=None)
    drop_in = "mjx_pusht/PushT-gym-pusht-v0"
    if drop_in not in gym.registry:
        gym.register(id=drop_in, entry_point="mjx_pusht.envs.gym_pusht:GymPushTEnv",
                     vector_entry_point="mjx_pusht.envs.gym_pusht:GymPushTVectorEnv", max_episode_steps=300,
                     kwargs={"obs_type": "state"})
