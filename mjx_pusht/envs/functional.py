"""PushT as a functional environment, in the style of gymnax and MuJoCo Playground.

    env = PushTEnv(backend="mjx-jax")          # or "cpu", "mjx-warp"; PushTEnv.for_task("gym-pusht", ...)
    state = env.reset(np.arange(1024))         # one episode per seed
    state = env.step(state, actions)           # actions (N, 2); every field of state is (N, ...)

`step` is the control step every rollout runs (episode.py): the action becomes servo ctrl
(`task.to_ctrl`), `frame_skip` physics steps follow, each folded into the weld-gap, finite and
containment invariants, then reward = coverage, and the episode ends at coverage >= 0.95 (`terminated`;
`for_task(..., success_threshold=)`: another) or after `max_steps` control steps (`truncated`). An ended
episode holds still and earns nothing. `goal="random"`: a goal per episode, obs["goal"] (task/goals.py).

On MJX `step_one(state, action)` is the pure single-world function: `step` is
`jax.jit(jax.vmap(step_one))`, and a user may vmap, jit or scan it as they like. On `cpu` the
same call takes NumPy arrays and steps MuJoCo C (the state holds its own copies of the MjData,
so an old state stays valid). `reset` draws start poses on the host from each seed's own
generator (reset.py), the same on every backend.

`pixels=96` adds obs["pixels"], (N, 96, 96, 3) uint8 from the top camera (pixels.py): rendered
inside the jitted step on MJX-Warp, by MuJoCo C's renderer on cpu. `reset_where` starts new
episodes in some rows and leaves the rest running (a vector env's autoreset).

This module builds the env and steps it; its resets are in resets.py, its observations in observation.py,
its `State` in state.py (importable from here, as before).
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

import numpy as np

from mjx_pusht import boundary, validate
from mjx_pusht.api import keyword_checked, keywords
from mjx_pusht.envs import physics as per_episode
from mjx_pusht.envs.observation import Observes
from mjx_pusht.envs.resets import Resets
from mjx_pusht.envs.starts import episode_with_goal
from mjx_pusht.envs.state import State, check_state
from mjx_pusht.errors import ConfigError
from mjx_pusht.model.layout import QposLayout
from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.task.controllers import Controller
from mjx_pusht.task.episode import Episode, control_step
from mjx_pusht.task.rules import ACTION_TYPES

__all__ = ["ENV_GRAPH_MODE", "PushTEnv", "State"]


# The env steps one control step per call, from buffers XLA hands it anew each call: staged, Warp replays
# one graph whatever the addresses. Measured on an H100 (notebook change 13): the gymnasium vector env,
# torch output, 237k / 650k / 1.17 M control steps/s at 4,096 / 16,384 / 65,536 envs, against 114k /
# 431k / out of memory with "WARP".
ENV_GRAPH_MODE = "WARP_STAGED"


class _Stateless(Controller):
    """The environment takes actions from outside; its episode carry needs no controller state."""


@dataclasses.dataclass
class PushTEnv(Resets, Observes):
    """A batch of PushT episodes on one backend (cpu, mjx-jax, mjx-warp).

    Its resets (`reset`, `reset_to`, `fresh_one`, `reset_where`) are inherited from `resets.Resets`, its
    observations (`with_pixels`, `images`, `renderer`, `close`) from `observation.Observes`: documented there."""

    backend: str = "cpu"
    reset_kind: str = "task"
    action_type: str = "velocity"
    episode: Episode = Episode()
    scene: SceneSpec = SceneSpec()
    pixels: int = 0  # image size for obs["pixels"]; 0: no images
    keypoints: bool = True  # obs["keypoints"]; False spares computing them where nothing reads them
    goal: str = "fixed"  # task/goals.GOALS: the target at the origin, or a goal per episode from its seed (obs["goal"])
    threads: int = 1  # cpu: worlds stepped on this many threads at once (same bits as one)
    # cpu: False steps the MjData in place (an old state is then stale): what a stateful vector env wants
    keep_states: bool = True
    # MJX-Warp: contacts and constraint rows per world; None: the sweep's start sizes (backends/warp.py)
    contacts_per_world: int | None = None
    rows_per_world: int | None = None
    # MJX-Warp's CUDA-graph mode, a name of warp.JaxCallableGraphMode. None: "WARP_STAGED" (Warp copies the
    # step's inputs into buffers of its own and replays one captured graph), the env's measured best
    # (notebook change 13); "WARP" is MJX's default, which the sweep keeps
    graph_mode: str | None = None
    randomize: Any = None  # {name: (lo, hi)} scale factors drawn per episode from its seed (model/randomize.py)
    # MJX: obs["pixels"] drawn by the raster renderer (render/raster.py: plain JAX ops, so any MJX backend and any
    # device, under shard_map too; the same bytes as MJX-Warp's ray tracer on every state tested) instead of MJX-Warp's
    raster: bool = False

    def __post_init__(self) -> None:
        from mjx_pusht.backends.base import BackendError
        from mjx_pusht.scenario import Scenario

        given = {k: getattr(self, k) for k in boundary.FUNCTIONAL_ENV}
        boundary.check(boundary.FUNCTIONAL_ENV, given, "PushTEnv")
        boundary.refuse_combinations(boundary.COMBINATIONS["functional_env"], given)
        boundary.OneOf(tuple(ACTION_TYPES))("action type", self.action_type)  # an array is refused, not compared
        self.pixels, self.threads = validate.pixels(self.pixels), validate.positive_int("threads", self.threads)
        self.episode = episode_with_goal(self.episode, self.goal, self.scene.variant)
        if self.backend not in ("cpu", "mjx-jax", "mjx-warp"):
            raise BackendError(f"the environment runs on cpu, mjx-jax or mjx-warp, not {self.backend!r}")
        if self.scene.variant == "gym-pusht" and self.reset_kind == "task":
            self.reset_kind = "gym-pusht"  # the variant's own reset, unless another is asked for
        self._ctrl = _Stateless(action_type=self.action_type)
        self.scenario = Scenario(self.scene, reset=self.reset_kind, controller=self._ctrl, episode=self.episode,
                                 randomize=self.randomize)
        self._settle = self.scenario.schedule.settle_steps - 1
        if self.backend == "cpu":
            from mjx_pusht.backends.cpu import cpu_model

            self.model = cpu_model(self.scenario)
            self._xp = np
            self._cpu_renderer = None
        else:
            import jax.numpy as jnp

            from mjx_pusht.backends.base import IMPL
            from mjx_pusht.backends.mjx import MjxConfig, MjxRunner

            impl = IMPL[self.backend]
            # MJX-Warp's buffers as the sweep sizes them (the measured need with headroom), not at the
            # scene's geometric bound, whose EPA scratch alone is 16 GB at 65,536 worlds. Every step's
            # overflow bits are kept in the state (`dropped`), and `check` raises on them: a step that
            # dropped a contact is never handed on as physics.
            # MJX_PUSHT_ENV_GRAPH_MODE: the benchmarks' knob to compare CUDA-graph modes (benchmarks/env_loop.py)
            self.graph_mode = self.graph_mode or os.environ.get("MJX_PUSHT_ENV_GRAPH_MODE")
            if impl == "warp" and self.graph_mode is None:
                from mjx_pusht.backends.base import has_gpu

                self.graph_mode = ENV_GRAPH_MODE if has_gpu() else None  # Warp captures graphs on CUDA only
            if impl == "warp" and self.graph_mode is not None:
                import warp as wp

                modes = list(wp.JaxCallableGraphMode.__members__)
                if self.graph_mode not in modes:
                    raise ConfigError(f"unknown graph mode {self.graph_mode!r}; choose from {', '.join(modes)}")
            else:
                self.graph_mode = None  # MJX-JAX has no FFI call to capture
            from mjx_pusht.backends.warp import (
                ENV_ROWS_PER_WORLD,
                START_CONTACTS_PER_WORLD,
            )

            cfg = MjxConfig(impl=impl, contacts_per_world=self.contacts_per_world or START_CONTACTS_PER_WORLD,
                            constraints_per_world=self.rows_per_world or ENV_ROWS_PER_WORLD, graph_mode=self.graph_mode)
            self.runner = MjxRunner(self.scenario, cfg)
            self.model = self.runner.model
            self._xp = jnp
            self._mx = self.runner.models.first()
            if self.pixels and impl != "warp" and not self.raster:
                from mjx_pusht.render.pixels import PixelsError

                raise PixelsError("pixel observations on MJX-JAX need the raster renderer (raster=True): or use "
                                  "backend mjx-warp (MJX-Warp's ray tracer), or cpu")
            self._renderers, self._jitted, self._templates = {}, {}, {}
        self.layout = QposLayout.of(self.model)

    @classmethod
    @keywords  # a missing task, or one given twice: one line
    def for_task(cls, task: str, backend: str = "cpu", max_steps: int | None = None,
                 success_threshold: float | None = None, **kwargs) -> "PushTEnv":
        """A task's env (task/tasks.TASKS): its scene, starts, actions and episodes (success at `success_threshold`)."""
        from mjx_pusht.task.tasks import get

        if given := sorted(set(kwargs) & {"reset_kind", "action_type", "episode", "scene"}):
            raise ConfigError(f"PushTEnv.for_task({task!r}) takes {', '.join(given)} from the task: give the other "
                              "settings here, or build PushTEnv(...) with your own")
        t = get(task)
        return cls(backend, t.reset, t.action_type, t.episode(max_steps, success_threshold=success_threshold),
                   t.scene(), **kwargs)


    # -- step -------------------------------------------------------------------------------------
    def step_one(self, state: State, action) -> State:
        """One world's control step (MJX): pure, jit- and vmap-able."""
        return self.with_pixels(self.advance_one(state, action))


    def advance_one(self, state: State, action) -> State:
        """One world's control step without the image (pure)."""
        import jax.numpy as jnp

        from mjx_pusht.backends.mjx_step import physics_for

        mx = per_episode.world_model(self, state.physics)
        step = physics_for(mx, self.episode.frame_skip, self._settle, self.layout, self.backend == "mjx-warp")
        sim = (state.data, jnp.zeros((), jnp.int32), None)
        qpos, carry, (d, ovf, _) = control_step(sim, state.carry, state.data.qpos, state.step, action,
                                                self.action_type, step, self.layout, self.episode, jnp)
        new = self._after(state, d, carry, jnp, pixels=False)
        return new if state.dropped is None else new._replace(dropped=state.dropped | ovf)

    def _after(self, state, data, carry, xp, pixels=True, qvel=None) -> State:
        # An episode over at reset (a start on the goal) reports its end at its first step, with the reward of the
        # coverage it ended at: terminated and reward agree. After that an ended episode holds still, earning 0.
        held = state.carry["ep"]["done"] & ~((state.step == 0) & state.terminated)
        qpos = data.qpos if not isinstance(data, np.ndarray) else data
        ep = carry["ep"]
        if isinstance(held, np.ndarray) and not held.any():  # the host's usual step: nothing held, no selects
            step, reward = state.step + 1, ep["coverage"].astype(np.result_type(0.0, ep["coverage"]))
        else:
            step = xp.where(held, state.step, state.step + 1)
            reward = xp.where(held, 0.0, ep["coverage"])
        terminated = ep["done"] & ep["success"]
        truncated = ~terminated & (step >= self.episode.max_steps)
        carry = {**carry, "ep": {**ep, "done": ep["done"] | truncated}}
        obs = self._observe(qpos, data, pixels, qvel, carry.get("goal"))
        return State(data, carry, obs, reward, terminated, truncated, step, state.key, state.dropped, state.info,
                     state.physics)


    def _step_cpu(self, state: State, action) -> State:
        """The batch's control step on MuJoCo C: the same episode.py functions on NumPy arrays."""
        check_state(state, self.backend, self)
        return self._step_checked(state, validate.actions(action, (len(state.step), 2), -np.inf, np.inf))

    def _step_checked(self, state: State, action: np.ndarray) -> State:
        """`_step_cpu` of actions already through `validate.actions` (a gymnasium env checks its own)."""
        from mjx_pusht.backends.cpu import cpu_physics
        from mjx_pusht.envs.row import unstable

        worlds = state.data.copy() if self.keep_states else state.data
        physics = self.__dict__.get("_cpu_physics")
        if physics is None:
            physics = self._cpu_physics = cpu_physics(self.layout, self.episode.frame_skip, self._settle)
        qpos = state.data.qpos[-1]
        qpos, carry, _ = control_step((worlds, None), state.carry, qpos, state.step, action, self.action_type, physics,
                                      self.layout, self.episode, np)
        reset = unstable(worlds)  # a world MuJoCo reset (its state went non-finite): never finite again
        if reset.any():
            carry = {**carry, "inv": {**carry["inv"], "finite": carry["inv"]["finite"] & ~reset}}
        return self._after(state, qpos, carry, np, qvel=worlds.qvel[-1])._replace(data=worlds)

    @keywords  # a missing argument or an unknown keyword: one line naming what it takes
    def step(self, state: State, action) -> State:
        # one step for both (an instance's own step on MJX skipped the keyword check: Python's TypeError for
        # step(state, a, bogus=1) there, the package's line on cpu: the thirteenth pass)
        return self._step_cpu(state, action) if self.backend == "cpu" else self._step_mjx(state, action)

    # -- MJX: one compiled step per batch size (the renderer's buffers are sized to the batch) --------
    def _batch_fns(self, n: int):
        import jax

        if n not in self._jitted:
            if self.pixels and self.raster:
                from mjx_pusht.render.raster import Raster

                self._renderers[n] = Raster(self.model, self.pixels)
            elif self.pixels:
                from mjx_pusht.render.pixels import WarpRenderer

                self._renderers[n] = WarpRenderer(self.model, n, self.pixels)
            self._jitted[n] = (jax.jit(jax.vmap(self.step_one)), jax.jit(self._reset_batch))
        self._renderer = self._renderers.get(n)
        return self._jitted[n]

    def _step_mjx(self, state: State, action) -> State:
        import jax
        import jax.numpy as jnp

        check_state(state, self.backend, self)
        action = jnp.asarray(action)
        validate.actions_shape_on_device(action, len(state.step))  # (n, 2), never reshaped; traced too
        if not isinstance(action, jax.core.Tracer):
            validate.actions_on_device(action, len(state.step), jnp)
        return self._batch_fns(len(state.step))[0](state, action)

    def check(self, state: State) -> State:
        """Raise `BufferOverflow` if any world of `state` dropped a contact or a constraint row in its episode
        (MJX-Warp); call it after a jitted scan of `step_one`. Returns the state, so it chains."""
        boundary.Instance(State, "a State (what reset and step return)")("state", state)  # None: an AttributeError
        if state.dropped is not None:
            from mjx_pusht.backends.warp import dropped

            bits = np.asarray(state.dropped)
            if dropped(bits).any():
                self.runner.buffers.check(bits)
        return state


# an unknown keyword (`PushTEnv.for_task('gym-pusht', bogus=1)`, any public method's): one line naming the known ones
keyword_checked(PushTEnv)
