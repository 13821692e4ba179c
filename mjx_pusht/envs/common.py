"""What the gymnasium envs share: spaces, the functional env behind them, pictures, and the broken-world warning.

NumPy only at import and on the CPU path: a CPU env neither needs nor initialises JAX, so it
can be made in a parent process and forked (gymnasium's AsyncVectorEnv under `fork`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from gymnasium import spaces

from mjx_pusht import validate
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.row import applies, step_row
from mjx_pusht.envs.starts import START_HI, START_LO
from mjx_pusht.render.pixels import IMAGE_SIZE
from mjx_pusht.task.rules import ACTION_TYPES, CTRL_LIMIT, WORKSPACE_HALF

OBS_TYPES = ("state", "keypoints", "pixels", "pixels_agent_pos")
TABLE_HALF = 0.45  # every position in an observation lies on the table (the walls stop the bodies sooner)
NEVER = 2**31 - 1  # an env's own step limit when gymnasium's TimeLimit ends its episodes


def check_kwargs(obs_type: str, action_type: str, observation_size: int = IMAGE_SIZE) -> None:
    validate.choice("obs_type", obs_type, OBS_TYPES)
    validate.choice("action_type", action_type, ACTION_TYPES)
    validate.image_size(observation_size, "observation_size")  # the space's shape even where no image is drawn


def check_starts(starts, rows: int) -> np.ndarray:
    """reset_to_state in this env's units: [tee x, y, yaw, pusher x, y], metres and radians, inside the walls."""
    return validate.starts(starts, rows, START_LO, START_HI)


def action_bounds(action_type: str) -> tuple[float, float]:
    limit = CTRL_LIMIT if action_type == "velocity" else WORKSPACE_HALF
    return -limit, limit


def single_spaces(obs_type: str, action_type: str, size: int, dtype, goal: bool = False):
    """The observation and action space of one environment (`goal`: random goals, observed beside the T)."""
    img = spaces.Box(0, 255, (size, size, 3), np.uint8)
    agent = spaces.Box(-TABLE_HALF, TABLE_HALF, (2,), dtype)
    if obs_type == "state":
        hi = np.array([TABLE_HALF] * 4 + [math.pi] + ([TABLE_HALF] * 2 + [math.pi] if goal else []))
        obs = spaces.Box(-hi, hi, hi.shape, dtype)
    elif obs_type == "keypoints":
        obs = spaces.Box(-TABLE_HALF, TABLE_HALF, (32 if goal else 16,), dtype)
    elif obs_type == "pixels":
        obs = img
    else:
        obs = spaces.Dict({"pixels": img, "agent_pos": agent})
    lo, hi = action_bounds(action_type)
    return obs, spaces.Box(lo, hi, (2,), np.float32)


def warn_broken(info: dict) -> None:
    """A diverged or escaped world is physics gone wrong: say so, never just hand its numbers on."""
    bad = ~(np.asarray(info["finite"], bool) & np.asarray(info["contained"], bool))
    if np.any(bad):
        import warnings

        warnings.warn(f"mjx_pusht: {int(np.sum(bad))} environment(s) went non-finite or left the walls "
                      "(info['finite'], info['contained'] are False): their observations are not physics",
                      RuntimeWarning, stacklevel=3)


def functional(backend: str, obs_type: str, action_type: str, observation_size: int, reset_kind: str,
               max_episode_steps: int | None, frame_skip: int, threads: int = 1, variant: str = "chapter",
               success_threshold: float | None = None, goal: str = "fixed", randomize=None) -> PushTEnv:
    """The functional env behind the gymnasium envs; stepped in place (a gymnasium env keeps no old states).
    Its episodes are the variant's task's (task/tasks.py): the gym-pusht variant's run as gym-pusht's do (a start
    on the goal is scored by the first step), and success is at the task's coverage unless `success_threshold`.
    `max_episode_steps` None: no limit of the env's own (gymnasium's TimeLimit truncates). `goal`: task/goals.GOALS.
    `randomize`: physics drawn per episode from its seed (model/randomize.py), its values in info["physics"]
    (envs/physics.info)."""
    from mjx_pusht.task.tasks import get

    limit = NEVER if max_episode_steps is None else validate.positive_int("max_episode_steps", max_episode_steps)
    task = get(variant)  # each scene variant's own task has its name
    return PushTEnv(backend=backend, reset_kind=reset_kind, action_type=action_type,
                    pixels=observation_size if obs_type.startswith("pixels") else 0,
                    episode=task.episode(limit, validate.positive_int("frame_skip", frame_skip), success_threshold),
                    scene=task.scene(), threads=threads, keep_states=False,
                    keypoints=obs_type == "keypoints", goal=goal, randomize=randomize)


class OneWorld:
    """The single envs' control step: the functional env's, by the row step (envs/row.py: plain floats, the same
    bits) where it applies, else by the array path. `row_step = False` on an env takes the array path always."""

    row_step = True

    @property
    def success_threshold(self) -> float:
        """The coverage an episode succeeds (terminates) at, and the drop-in's reward scale (gym-pusht's attribute)."""
        return self._env.episode.success

    @success_threshold.setter
    def success_threshold(self, value: float) -> None:
        # gym-pusht#24's workaround, `env.unwrapped.success_threshold = 0.9`, works on both ids, from the next step
        # (on PushT-v0 it made an attribute nothing read); the episode's own check refuses a value outside (0, 1]
        self._env.episode = dataclasses.replace(self._env.episode, success=value)

    def _step_world(self, x: float, y: float):
        """`self._state` stepped by the checked, clipped action (x, y) in the functional env's units."""
        state = self._state
        new = step_row(self._env, state, x, y) if self.row_step and applies(self._env, state) else None
        return new if new is not None else self._env._step_checked(state, np.array([[x, y]]))


class Pictures:
    """rgb_array pictures for the envs (the CPU renderer at `render_size`, made on demand), and closing what
    renders: only this env's own GL contexts, so closing one env never touches another's images."""

    _viewer = _window = None

    def _open_window(self) -> None:
        """render_mode='human': open the window now, so a machine without a display is refused at make. This
        instance's render modes are those that work here (render.window.render_modes)."""
        from mjx_pusht.render.window import render_modes

        self.metadata = {**self.metadata, "render_modes": render_modes(self.metadata["render_modes"])}
        if self.render_mode == "human":
            from mjx_pusht.render.window import Window

            self._window = Window(self.render_size, self._fps)

    def _shown(self, img: np.ndarray):
        """rgb_array: the picture; human: the picture in the window, and None (gymnasium's convention)."""
        if self._window is None:
            return img
        self._window.show(img)
        return None

    def _draw(self, qpos, goals=None) -> np.ndarray:
        """The pictures of (N, nq) positions, the target at each row's goal (`goals` (N, 3); None: the scene's)."""
        if self._viewer is None:
            from mjx_pusht.render.pixels import CpuRenderer

            self._viewer = CpuRenderer(self._env.model, self.render_size)
        return self._viewer(np.asarray(qpos, np.float64), None if goals is None else np.asarray(goals, np.float64))

    def _close_renderers(self) -> None:
        """Free this env's GL contexts (only its own); rendering after this makes new ones."""
        if self._viewer is not None:
            self._viewer.close()
        if self._window is not None:
            self._window.close()
        self._viewer = self._window = None
        if getattr(self, "_env", None) is not None and self._env.backend == "cpu":
            self._env.close()

    @property
    def _fps(self) -> int:
        return round(1 / (self._env.episode.frame_skip * self._env.model.opt.timestep))
