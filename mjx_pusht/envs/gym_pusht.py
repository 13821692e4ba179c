"""`mjx_pusht/PushT-gym-pusht-v0`: gym-pusht's interface, point for point, on this project's physics.

    env = gym.make("mjx_pusht/PushT-gym-pusht-v0", obs_type="pixels_agent_pos")   # was "gym_pusht/PushT-v0"
    envs = gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=16384)          # the batch, on the GPU if any

The same kwargs (obs_type, render_mode, observation_/visualization_width/height), spaces,
units (pixels of gym-pusht's 512 x 512 frame, y down; angles as pymunk's), action (an absolute
target in pixels, tracked by gym-pusht's PD law, kp 100 and kv 20 at 100 Hz, 10 Hz control),
reward clip(coverage / 0.95, 0, 1), success coverage > 0.95 (`success_threshold=`: another, in (0, 1], in both:
gym-pusht#24 asks for it; gym-pusht itself fixes it at 0.95), info keys, `reset_to_state` (with
its legacy placement quirk), registration with max_episode_steps=300 (gymnasium's TimeLimit, so
the kwarg and `_max_episode_steps` behave as they do for gym-pusht), and render_fps 10.

Underneath it is the `gym-pusht` scene variant (model/gym_pusht_scene.py) on the one functional env:
this file only converts units at the boundary (`gym_view`). A single env is MuJoCo C; the vector
env is `gym.PushTVectorEnv` (the batch, device autoreset, the full vector API), handing out
NumPy by default, as a gym-pusht loop expects (`array_type="torch"` or `"jax"` to stay on the GPU).
What still differs from pymunk's physics, measured, is docs/dropin-physics.md.

Beyond gym-pusht: `randomize={"kp": (0.8, 1.2), "kv": (0.8, 1.2)}` draws each episode's PD gains from its seed
(scale factors on gym-pusht's KP and KV, model/randomize.py), their values in info["physics"], as PushT-v0 does.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mjx_pusht.task import goals
from mjx_pusht import validate
from mjx_pusht.api import keywords
from mjx_pusht.envs import gym as base  # first: says which extra brings gymnasium if it is missing
from mjx_pusht.envs import physics
from mjx_pusht.envs.common import OneWorld, Pictures, functional, warn_broken
from mjx_pusht.envs.vector import PushTVectorEnv
from mjx_pusht.errors import ConfigError
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.reset import SEED_MAX, start_poses
from mjx_pusht.task.tasks import get as get_task
from mjx_pusht.task.rules import T_RECTS

spaces = base.gym.spaces

ENV_ID = "mjx_pusht/PushT-gym-pusht-v0"
OBS_TYPES = ("state", "environment_state_agent_pos", "pixels", "pixels_agent_pos")
TARGET_BOUNDS = (0.0, 512.0)  # the action space: targets are clipped to it, as PushT-v0 clips its actions
# reset_to_state [agent x, y, block x, y, angle] in pixels: both bodies in gym-pusht's 512-pixel window (its own
# docstring's example puts the agent at x = 0, in the wall, and gym-pusht takes it); the angle is unbounded
START_LO = np.array([0.0] * 4 + [np.nan])
START_HI = np.array([512.0] * 4 + [np.nan])
CONTACT_PX = 1.0  # a gap this small counts as touching (n_contacts)


def _check_kwargs(obs_type, width, height, render_mode, block_cog, damping, human: bool = False) -> None:
    validate.choice("obs_type", obs_type, OBS_TYPES)
    validate.image_size(width, "observation_width")
    validate.image_size(height, "observation_height")
    if width != height:
        raise ConfigError(f"images are square here: observation_width {width} != observation_height {height}")
    validate.render_mode(render_mode, human)
    if block_cog is not None or damping is not None:
        raise ConfigError("block_cog and damping are pymunk settings: this physics is MuJoCo's "
                          "(see docs/envs/dropin.md)")


def gym_pusht_spaces(obs_type: str, width: int = 96, height: int = 96, dtype=np.float64, goal: bool = False):
    """gym-pusht 0.1.8's observation and action spaces, as it builds them (`goal`: with random goals' beside the T's,
    its pose after the block's, its T's 8 vertices after the block's)."""
    if obs_type == "state":
        high = [512, 512, 512, 512, 2 * np.pi] + ([512, 512, 2 * np.pi] if goal else [])
        obs = spaces.Box(low=np.zeros(len(high)), high=np.array(high), dtype=dtype)
    elif obs_type == "environment_state_agent_pos":
        k = 32 if goal else 16
        obs = spaces.Dict({"environment_state": spaces.Box(low=np.zeros(k), high=np.full((k,), 512), dtype=dtype),
                           "agent_pos": spaces.Box(low=np.array([0, 0]), high=np.array([512, 512]), dtype=dtype)})
    else:
        img = spaces.Box(low=0, high=255, shape=(height, width, 3), dtype=np.uint8)
        obs = img if obs_type == "pixels" else spaces.Dict(
            {"pixels": img, "agent_pos": spaces.Box(low=np.array([0, 0]), high=np.array([512, 512]), dtype=dtype)})
    return obs, spaces.Box(low=0, high=512, shape=(2,), dtype=np.float32)


def gym_view(obs_type: str, obs: dict, coverage, terminated, xp, dtype):
    """The functional env's world-frame observation (batched or not) as gym-pusht's (obs, info), in pixels."""
    s = obs["state"]
    agent = frame.to_px(s[..., 0:2], xp)
    origin, angle = frame.pose_to_px(s[..., 2:5], xp)
    corners = frame.keypoints_px(origin, angle, xp)
    if obs_type == "state":
        out = xp.concatenate([agent, origin, angle[..., None]], axis=-1).astype(dtype)
    elif obs_type == "environment_state_agent_pos":
        out = {"environment_state": corners.astype(dtype), "agent_pos": agent.astype(dtype)}
    elif obs_type == "pixels":
        out = obs["pixels"]
    else:
        out = {"pixels": obs["pixels"], "agent_pos": agent.astype(dtype)}
    info = {
        "pos_agent": agent,
        "vel_agent": frame.velocity_to_px(obs["pusher_vel"], xp),
        # gym-pusht's info gives its body's own angle, unwrapped (its observation wraps it to [0, 2 pi)): the hinge's
        "block_pose": xp.concatenate([origin, (_GOAL_YAW - s[..., 4])[..., None]], axis=-1),
        "goal_pose": _goal(origin.shape[:-1] + (3,), agent.dtype, xp),
        "n_contacts": n_contacts(s[..., 0:2], s[..., 2:5], corners, xp),
        "is_success": terminated,
        "coverage": coverage,
    }
    if "goal" in obs:  # a random goal, as gym-pusht would show its goal_pose: beside the block, and in info
        g_origin, g_angle = frame.pose_to_px(obs["goal"], xp)
        info["goal_pose"] = xp.concatenate([g_origin, g_angle[..., None]], axis=-1)
        if obs_type == "state":
            out = xp.concatenate([out, info["goal_pose"].astype(dtype)], axis=-1)
        elif obs_type == "environment_state_agent_pos":
            goal_corners = frame.keypoints_px(g_origin, g_angle, xp).astype(dtype)
            out = {**out, "environment_state": xp.concatenate([out["environment_state"], goal_corners], axis=-1)}
    return out, info


def gym_view_row(obs_type: str, obs: dict, coverage: float, terminated: bool):
    """`gym_view` of one world's host observation (`obs` rows of shape (5,), (2,)) in Python floats: the same
    operations in the same order (NumPy's cos and sin of the angle, as the array code's), the same bits
    (tests/test_row_step.py), without its ~40 array calls on one-row arrays (the drop-in's step)."""
    px, py, tx, ty, yaw = obs["state"].tolist()
    ax, ay = _px(px, py)
    angle = (_GOAL_YAW - yaw) % (2 * math.pi)
    bx, by = _px(tx, ty)
    c, s = float(np.cos(angle)), float(np.sin(angle))
    ox, oy = bx + s * frame.ORIGIN_PX, by - c * frame.ORIGIN_PX
    corners = [v for kx, ky in _KEYPOINTS for v in (c * kx - s * ky + ox, s * kx + c * ky + oy)]
    agent = np.array([ax, ay])
    if obs_type == "state":
        out = np.array([ax, ay, ox, oy, angle])
    elif obs_type == "environment_state_agent_pos":
        out = {"environment_state": np.array(corners), "agent_pos": np.array([ax, ay])}
    elif obs_type == "pixels":
        out = obs["pixels"]
    else:
        out = {"pixels": obs["pixels"], "agent_pos": np.array([ax, ay])}
    vx, vy = obs["pusher_vel"].tolist()
    lx, ly = vx / frame.PX, -vy / frame.PX
    lo, hi = frame.WALL_INNER_PX
    if c - c == 0 and s - s == 0 and ox - ox == 0 and oy - oy == 0:  # every corner finite: min and max are exact
        wall = min(corners) <= lo + CONTACT_PX or max(corners) >= hi - CONTACT_PX
    else:
        wall = any(v <= lo + CONTACT_PX or v >= hi - CONTACT_PX for v in corners)
    touch = _distance_to_tee(px, py, tx, ty, yaw) <= (frame.AGENT_RADIUS_PX + CONTACT_PX) * frame.PX
    info = {
        "pos_agent": agent,
        "vel_agent": np.array([_GC * lx - _GS * ly, _GS * lx + _GC * ly]),
        "block_pose": np.array([ox, oy, _GOAL_YAW - yaw]),  # unwrapped, as gym-pusht's (gym_view)
        "goal_pose": np.array(frame.GOAL_PX),
        "n_contacts": int(touch or wall),
        "is_success": terminated,
        "coverage": coverage,
    }
    return out, info


_GOAL_YAW = frame.GOAL_PX[2]
_GC, _GS = math.cos(_GOAL_YAW), math.sin(_GOAL_YAW)  # frame.to_px's and velocity_to_px's rotation
_WC, _WS = math.cos(-_GOAL_YAW), math.sin(-_GOAL_YAW)  # frame.to_world's
_KEYPOINTS = [tuple(k) for k in frame.KEYPOINTS_LOCAL_PX.tolist()]


def _px(x: float, y: float) -> tuple[float, float]:
    """`frame.to_px` of one world position, in floats."""
    lx, ly = x / frame.PX, frame.ORIGIN_PX - y / frame.PX
    return _GC * lx - _GS * ly + frame.GOAL_PX[0], _GS * lx + _GC * ly + frame.GOAL_PX[1]


def _world(x: float, y: float) -> tuple[float, float]:
    """`frame.to_world` of one pixel position, in floats."""
    dx, dy = x - frame.GOAL_PX[0], y - frame.GOAL_PX[1]
    lx, ly = _WC * dx - _WS * dy, _WS * dx + _WC * dy
    return lx * frame.PX, (frame.ORIGIN_PX - ly) * frame.PX


def _distance_to_tee(x: float, y: float, tx: float, ty: float, yaw: float) -> float:
    """`rules.distance_to_tee` of one point and pose, in floats (NumPy's cos and sin, minimum and maximum's NaN)."""
    c, s = float(np.cos(yaw)), float(np.sin(yaw))
    dx, dy = x - tx, y - ty
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    out = None
    for cx, cy, hx, hy in T_RECTS:
        ox, oy = abs(lx - cx) - hx, abs(ly - cy) - hy
        ox, oy = (ox if ox >= 0.0 or ox != ox else 0.0), (oy if oy >= 0.0 or oy != oy else 0.0)
        d = math.sqrt(ox * ox + oy * oy)
        out = d if out is None or d != d or (d < out and out == out) else out
    return out


def n_contacts(pusher_xy, tee_pose, corners_px, xp):
    """gym-pusht's n_contacts, which its formula makes 1 when anything touched in the step and 0 otherwise
    (contact points / 1000, rounded up): here 1 when the pusher touches the T or a corner of the T
    touches a wall (within CONTACT_PX), from the world poses and the T's corners in pixels."""
    from mjx_pusht.task.rules import distance_to_tee

    pusher = distance_to_tee(pusher_xy, tee_pose) <= (frame.AGENT_RADIUS_PX + CONTACT_PX) * frame.PX
    lo, hi = frame.WALL_INNER_PX
    wall = xp.any((corners_px <= lo + CONTACT_PX) | (corners_px >= hi - CONTACT_PX), axis=-1)
    return (pusher | wall).astype(xp.int64 if xp is np else xp.int32)


def reward_of(coverage, threshold: float, xp):
    """gym-pusht's reward, clip(coverage / success threshold, 0, 1)."""
    # clip as minimum(maximum()): what np.clip and jnp.clip compute, without np.clip's checks
    return xp.minimum(xp.maximum(coverage / threshold, 0.0), 1.0)


def _goal(shape, dtype, xp):
    """gym-pusht's goal pose in every row: on the host a new array filled with it (np.broadcast_to's
    Python-level checks cost more than the copy for one env), elsewhere a broadcast."""
    if xp is np:
        out = np.empty(shape, dtype)
        out[...] = frame.GOAL_PX
        return out
    return xp.broadcast_to(xp.asarray(frame.GOAL_PX, dtype=dtype), shape)


def _check_state(state, rows: int) -> np.ndarray:
    """reset_to_state in gym-pusht's convention: [agent x, y, block x, y, angle], pixels and radians, both
    bodies in the window; returned in the world frame."""
    a = validate.starts(state, rows, START_LO, START_HI, "[agent x, y, block x, y, block angle] in pixels")
    lo, hi = frame.WALL_INNER_PX
    walled = ((a[:, :4] < lo) | (a[:, :4] > hi)).any(axis=1)
    if walled.any():  # taken, as gym-pusht takes it (its docstring's own example puts the agent at x = 0), but said:
        import warnings  # a body there is pushed out at the first step (the thirteenth pass: a T at (0, 0) px jumped)

        r = int(np.flatnonzero(walled)[0])
        warnings.warn(f"reset_to_state puts the agent or the block in gym-pusht's walls (their inner faces are at "
                      f"{lo:g} and {hi:g} px), row {r}: {a[r].tolist()}; gym-pusht takes such a start, and its first "
                      "step pushes the body back inside, as here", stacklevel=3)
    return frame.legacy_state_to_world(a)


def _marker(img: np.ndarray, action, size: int) -> np.ndarray:
    """gym-pusht's red cross at the last action (cv2.drawMarker, MARKER_CROSS, its sizes)."""
    half, t = int(8 / 96 * size) // 2, max(1, int(1 / 96 * size))
    x, y = (np.asarray(action, np.float64) / 512 * size).astype(int)
    img = img.copy()
    lo = -(t // 2)
    img[max(0, y + lo):max(0, y + lo + t), max(0, x - half):max(0, x + half + 1)] = (255, 0, 0)
    img[max(0, y - half):max(0, y + half + 1), max(0, x + lo):max(0, x + lo + t)] = (255, 0, 0)
    return img


class GymPushTEnv(OneWorld, Pictures, base.gym.Env):
    """One episode at a time on MuJoCo C, with gym-pusht's interface. Resets draw from the env's generator
    exactly as gym-pusht's do, so `reset(seed=s)` and every later reset start where gym-pusht's start."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    @keywords  # an unknown keyword: one line naming the known ones
    def __init__(self, obs_type: str = "state", render_mode: str | None = "rgb_array", block_cog=None, damping=None,
                 observation_width: int = 96, observation_height: int = 96, visualization_width: int = 680,
                 visualization_height: int = 680, success_threshold: float | None = None, reset_kind: str = "gym-pusht",
                 goal: str = "fixed", randomize=None):
        _check_kwargs(obs_type, observation_width, observation_height, render_mode, block_cog, damping, human=True)
        validate.choice("reset_kind", reset_kind, get_task("gym-pusht").resets + get_task("gym-pusht-easy").resets)
        validate.image_size(visualization_width, "visualization_width")
        validate.image_size(visualization_height, "visualization_height")
        if visualization_width != visualization_height:
            raise ConfigError(f"renders are square here: visualization_width {visualization_width} != "
                              f"visualization_height {visualization_height}")
        self.obs_type, self.render_mode = obs_type, render_mode
        self.observation_width, self.observation_height = observation_width, observation_height
        self.visualization_width, self.visualization_height = visualization_width, visualization_height
        self.render_size = visualization_width
        self.observation_space, self.action_space = gym_pusht_spaces(obs_type, observation_width, observation_height,
                                                                     goal=goals.check(goal) != "fixed")
        self.k_p, self.k_v, self.control_hz, self.dt = frame.KP, frame.KV, 10, 0.01  # as gym-pusht names them
        self._env = functional("cpu", obs_type, "target", observation_width, reset_kind, None, 10,
                               variant="gym-pusht", success_threshold=success_threshold, goal=goal, randomize=randomize)
        self._state, self._last_action, self._seed = None, None, -1
        self._open_window()

    @keywords  # (not step: the hot path, where gymnasium's wrappers meet a stray keyword first)
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        seed = validate.seed(seed)
        options = validate.reset_options(options, ("reset_to_state",), type(self).__name__)
        super().reset(seed=seed)
        if "reset_to_state" in options:
            start = _check_state(options["reset_to_state"], 1)
        elif self._env.reset_kind == "gym-pusht":  # gym-pusht's draws, in its order, from this env's generator
            r = self.np_random
            start = frame.legacy_state_to_world([r.integers(50, 450), r.integers(50, 450), r.integers(100, 400),
                                                 r.integers(100, 400), r.uniform(-np.pi, np.pi)])
        else:  # another start distribution (`easy`): the seed's start, as the functional env's (PushT-v0's rule)
            seed = seed if seed is not None else int(self.np_random.integers(SEED_MAX))
            start = start_poses([seed], reset=self._env.reset_kind)
        # the episode's seed, which draws its physics (randomize) and its goal (goal="random"): the one given, else
        # the one after the last episode's (gym-pusht's starts come from the generator: drawing a seed there would
        # change them)
        self._seed = seed if seed is not None else (self._seed + 1) % (SEED_MAX + 1)
        self._state = self._env.reset_to(start, [self._seed])
        self._last_action = None
        obs, info = self._view()
        info["is_success"] = False
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action):
        x, y = base.one_action(self._state, action, "(x, y) target in pixels", *TARGET_BOUNDS)
        self._last_action = (x, y)
        self._state = self._step_world(*_world(x, y))  # finite: (x, y) was checked
        obs, info = self._view()
        if self.render_mode == "human":
            self.render()
        return obs, float(info["reward"]), bool(info["is_success"]), False, info

    def _view(self):
        s = self._state
        m = s.metrics
        cov = m["coverage"].item()
        if "goal" in s.obs:  # random goals: the array view of this one row (the row view knows the fixed goal only)
            obs, info = gym_view(self.obs_type, s.obs, m["coverage"], s.terminated, np, np.float64)
            obs = {k: v[0] for k, v in obs.items()} if isinstance(obs, dict) else obs[0]
            info = {k: v[0] for k, v in info.items()}
        else:
            obs, info = gym_view_row(self.obs_type, {k: v[0] for k, v in s.obs.items()}, cov, bool(s.terminated[0]))
        info = {**info, "reward": min(max(cov / self.success_threshold, 0.0), 1.0),  # reward_of, on a float
                "finite": bool(m["finite"][0]), "contained": bool(m["contained"][0])}
        if not (info["finite"] and info["contained"]):
            warn_broken(info)
        return obs, info | physics.info(self._env, None if s.physics is None else s.physics[0])

    @keywords
    def render(self):
        """rgb_array: the picture (with gym-pusht's cross at the last target); human: shown in the window."""
        if self.render_mode is None:
            return None
        validate.started(self._state, "render")
        img = self._draw(self._state.data.qpos[-1], self._state.carry.get("goal"))[0]
        return self._shown(img if self._last_action is None else _marker(img, self._last_action, self.render_size))

    def close(self):
        self._close_renderers()


class GymPushTVectorEnv(PushTVectorEnv):
    """The batch (`gym.PushTVectorEnv`: any backend, device autoreset, the vector API) with gym-pusht's
    kwargs, spaces, units and infos; NumPy out by default, as a gym-pusht loop expects."""

    @keywords  # an unknown keyword: one line naming the known ones
    def __init__(self, num_envs: int = 1, obs_type: str = "state", render_mode: str | None = "rgb_array",
                 block_cog=None, damping=None, observation_width: int = 96, observation_height: int = 96,
                 visualization_width: int = 680, visualization_height: int = 680, max_episode_steps: int = 300,
                 backend: str = "auto", autoreset_mode="next_step", array_type: str | None = "numpy",
                 threads: int | None = None, depth: int = 8, success_threshold: float | None = None,
                 reset_kind: str = "gym-pusht", goal: str = "fixed", randomize=None):
        _check_kwargs(obs_type, observation_width, observation_height, render_mode, block_cog, damping)
        self.observation_width, self.observation_height = observation_width, observation_height
        self.visualization_width, self.visualization_height = visualization_width, visualization_height
        validate.choice("reset_kind", reset_kind, get_task("gym-pusht").resets + get_task("gym-pusht-easy").resets)
        super().__init__(num_envs, backend, obs_type, "target", render_mode, observation_width, visualization_width,
                         reset_kind, max_episode_steps, 10, autoreset_mode, threads, array_type, depth,
                         variant="gym-pusht", success_threshold=success_threshold, goal=goal, randomize=randomize)

    @staticmethod
    def _check_args(obs_type, action_type, observation_size):
        pass  # checked by _check_kwargs, in gym-pusht's terms

    @staticmethod
    def _single_spaces(obs_type, action_type, size, dtype, goal=False):
        return gym_pusht_spaces(obs_type, size, size, dtype, goal)

    @staticmethod
    def _starts_in(starts, rows):
        return _check_state(starts, rows)

    def _bounds(self) -> tuple[float, float]:
        return TARGET_BOUNDS

    def _actions_in(self, actions):
        xp = np if isinstance(actions, np.ndarray) or not hasattr(actions, "__array_namespace__") else \
            actions.__array_namespace__()
        a = xp.asarray(actions, dtype=np.float64 if self.backend == "cpu" else self._dtype)
        return frame.to_world(a, xp)

    def _view(self, flat: dict, xp):
        cov = flat["coverage"]
        obs, info = gym_view(self.obs_type, flat["obs"], cov, flat["terminated"], xp, self._dtype)
        info |= {"steps": flat["step"], "weld_gap_max_dev": flat["gap_max_dev"], "finite": flat["finite"],
                 "contained": flat["contained"]}
        reward = reward_of(flat["reward"], self._env.episode.success, xp)
        if xp is np:  # the host's convention, as SyncVectorEnv over gym-pusht's envs gives them
            info = {k: np.asarray(v, np.float64 if np.asarray(v).dtype.kind == "f" else
                                  (bool if np.asarray(v).dtype == bool else np.int64)) for k, v in info.items()}
            reward = np.asarray(reward, np.float64)
        every = xp.ones(self.num_envs, dtype=bool)
        return (obs, reward, flat["terminated"], flat["truncated"], info | {f"_{k}": every for k in info})

