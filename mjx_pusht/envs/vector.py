"""The batched vector env behind `gym.make_vec("mjx_pusht/PushT-v0", n)`: N worlds stepped as one batch.

One functional env (envs/functional.py) steps every world: one compiled program on MJX, MuJoCo C
on `threads` threads on the CPU, never N copies in subprocesses. Its inputs are checked by the one
validation layer (mjx_pusht/validate.py), as the single env's are. On the CPU backend nothing
here touches JAX.
"""

from __future__ import annotations

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from mjx_pusht.task import goals
from mjx_pusht import validate
from mjx_pusht.api import keyword_checked, keywords
from mjx_pusht.boundary import BYTES_PER_CPU_ENV, MAX_ENVS, fits
from mjx_pusht.envs import physics
from mjx_pusht.envs.common import (
    Pictures,
    action_bounds,
    check_kwargs,
    check_starts,
    functional,
    single_spaces,
    warn_broken,
)
from mjx_pusht.task.goals import with_goal
from mjx_pusht.envs.handoff import check_array_type, from_user, hand_off
from mjx_pusht.render.pixels import IMAGE_SIZE
from mjx_pusht.errors import ConfigError
from mjx_pusht.task.rules import wrap_angle

_METRICS = ("coverage", "gap_max_dev", "finite", "contained")


def _jnp():
    import jax.numpy as jnp

    return jnp


@keyword_checked  # reset, step, render too (the eleventh pass: reset(foo=1) was a TypeError)
class PushTVectorEnv(Pictures, VectorEnv):
    """N PushT episodes stepped as one batch on any backend (`auto`: MJX-Warp on a GPU, else MuJoCo C).

    Autoreset follows gymnasium's modes: `next_step` (the default: the step after an episode
    ends resets it and ignores its action), `same_step` (reset at once; the ended episode's
    observation and info go in info["final_obs"] / info["final_info"]) or `disabled`
    (reset(options={"reset_mask": mask}) resets the ones you pick). On MJX the autoreset runs
    on the device inside the jitted step (wrappers.AutoReset), from start poses drawn ahead
    by each env's own generator, so the episodes are those of gymnasium's SyncVectorEnv. With
    pixels in same_step mode the pool also holds those starts' first images, so a step renders
    once (wrappers.AutoReset): `depth` x num_envs x size^2 x 3 bytes of GPU memory (3.6 GB at
    16,384 envs of 96 x 96 and depth 8).

    `array_type`: what observations, rewards, flags and infos come out as: "jax" (the default
    on MJX: arrays on the device, no copy), "torch" (tensors on the same device through DLPack,
    no copy) or "numpy" (copied to the host; the only choice on cpu). Actions may be any of
    the three. Physics gone wrong is checked on the device and raised or warned about at least
    every `depth` // 2 steps (every step with NumPy output): a dropped contact (BufferOverflow),
    a non-finite or escaped world (RuntimeWarning).

    `randomize`: physics drawn per episode from its seed, as the single env's (model/randomize.py); each env's
    drawn values are in info["physics"] = {name: (num_envs,) values, "_name": mask}, with info["_physics"].
    """

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.NEXT_STEP}

    @keywords  # an unknown keyword: one line naming the known ones
    def __init__(self, num_envs: int = 1, backend: str = "auto", obs_type: str = "state",
                 action_type: str = "velocity", render_mode: str | None = None, observation_size: int = IMAGE_SIZE,
                 render_size: int = 512, reset_kind: str = "task", max_episode_steps: int = 300,
                 frame_skip: int = 10, autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
                 threads: int | None = None, array_type: str | None = None, depth: int = 8,
                 variant: str = "chapter", success_threshold: float | None = None, goal: str = "fixed",
                 randomize=None):
        from mjx_pusht.backends.base import resolve
        from mjx_pusht.backends.cpu import default_threads
        from mjx_pusht.envs.wrappers import AutoReset, StartPool

        self._check_args(obs_type, action_type, observation_size)
        self.num_envs = validate.positive_int("num_envs", num_envs, 1, MAX_ENVS)  # 2**40 was numpy's MemoryError
        validate.render_mode(render_mode)
        validate.image_size(render_size, "render_size")
        max_episode_steps = validate.episode_limit(max_episode_steps)  # -1 or None: no limit, as gymnasium says
        self.backend, _ = resolve(backend)
        if self.backend == "cpu":  # its worlds live in this machine's memory (an MJX batch's on the device)
            fits(f"num_envs={self.num_envs:,} on the cpu backend", self.num_envs, BYTES_PER_CPU_ENV,
                 "make fewer envs, or several vector envs one after another")
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
        threads = validate.threads(threads) or (min(default_threads(), max(1, self.num_envs // 64)) if self.backend == "cpu" else 1)
        self._env = functional(self.backend, obs_type, action_type, observation_size, reset_kind,
                                max_episode_steps, frame_skip, threads, variant, success_threshold, goal, randomize)
        self._dtype = np.float64 if self.backend == "cpu" else np.dtype(self._env.runner.dtype)
        self.single_observation_space, self.single_action_space = self._single_spaces(
            obs_type, action_type, observation_size, self._dtype, goals.check(goal) != "fixed")
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
        self._since_check = self._steps_since_reset = 0
        self._bad = []
        self._viewer = self._view_jit = None

    @property
    def success_threshold(self) -> float:
        """The coverage an episode succeeds (terminates) at (`success_threshold=` at make, or set after, as the
        single env's: every env of the batch from its next step on)."""
        return self._env.episode.success

    @success_threshold.setter
    def success_threshold(self, value: float) -> None:
        import dataclasses

        self._env.episode = dataclasses.replace(self._env.episode, success=value)  # checked: in (0, 1]
        # the MJX steps compiled the old threshold in as a constant: compiled again with the new one at the next step
        getattr(self._env, "_jitted", {}).clear()  # (none on cpu: its step reads the episode each call)
        if self._ar is not None:
            self._ar._jitted.clear()
        self._view_jit = None

    _check_args = staticmethod(check_kwargs)  # noqa: E303
    _single_spaces = staticmethod(single_spaces)
    _starts_in = staticmethod(check_starts)  # reset_to_state, in the env's units

    def _actions_in(self, actions):
        """Actions in the functional env's units (this env's are those already)."""
        return actions

    def _checked(self, actions):
        """(num_envs, 2) finite actions, clipped to the action space: NumPy on the host, device arrays (JAX, or
        torch through DLPack) by one reduction on their device."""
        actions = from_user(actions)
        if isinstance(actions, (np.ndarray, list, tuple, int, float)) or not hasattr(actions, "__array_namespace__"):
            return validate.actions(actions, (self.num_envs, 2), *self._bounds())
        xp = actions.__array_namespace__()
        if self._ar is None:  # no autoreset: every step is read on the host anyway
            validate.actions_on_device(actions, self.num_envs, xp)
            return xp.clip(actions, *self._bounds())
        # On the device loop the host reads the batch only every few steps (_step_device): a look at the values
        # here would wait for the device every step (measured on one H100: -16% at 16,384 state envs). The
        # check runs on the device; a non-finite row is held still (action 0) and named at the next read.
        validate.actions_shape_on_device(actions, self.num_envs)
        bad = ~xp.all(xp.isfinite(actions), axis=1)
        self._bad.append((self._steps_since_reset, bad, actions))
        return xp.clip(xp.where(bad[:, None], 0.0, actions), *self._bounds())

    def _bounds(self) -> tuple[float, float]:
        """The action space's bounds in float64 (the single env clips to the same numbers)."""
        return action_bounds(self.action_type)

    def reset(self, *, seed=None, options: dict | None = None):
        """Every env, or those in options["reset_mask"]; options["reset_to_state"] starts them from given states.
        Other options are ignored (as gym-pusht ignores them), seeds as SyncVectorEnv's (seed + i)."""
        if self.closed:
            raise ConfigError("the vector env is closed: make a new one to reset it")
        bad, self._bad = self._bad, []  # a device step's non-finite action not yet read is still an error
        validate.deferred_nonfinite(bad)
        seeds = validate.seed_list(seed, self.num_envs)
        options = validate.reset_options(options, ("reset_mask", "reset_to_state"), type(self).__name__)
        mask = validate.mask(options.get("reset_mask", np.ones(self.num_envs, bool)), self.num_envs)
        starts = options.get("reset_to_state")
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
        self._since_check = self._steps_since_reset = 0
        self._bad = []
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
        if self.closed:  # its renderers are gone; a step stepped on as if nothing happened
            raise ConfigError("the vector env is closed: make a new one to step again")
        validate.started(self._state)
        actions = self._checked(actions)
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
        self._steps_since_reset += 1
        if self.array_type == "numpy" or self._since_check >= max(1, self._pool.depth // 2):
            self._since_check = 0
            bad, self._bad = self._bad, []
            validate.deferred_nonfinite(bad)
            self._state = self._ar.refill(self._env.check(self._state))
            warn_broken({"finite": ~np.asarray(self._state.info["broken"]), "contained": True})
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
        if state.physics is not None:
            flat["physics"] = state.physics
        obs, reward, terminated, truncated, info = self._arrays(flat)
        if self.array_type == "numpy":
            warn_broken(info)
        return (obs, info) if reset else (obs, reward, terminated, truncated, info)

    def _arrays(self, flat: dict):
        """The gymnasium view of a state's arrays, then handed off: on the device in one jitted call,
        copied to the host first for NumPy."""
        keys = {"state", "pusher_vel", "goal"} | ({"keypoints"} if self.obs_type == "keypoints" else set()) | (
            {"pixels"} if self.obs_type.startswith("pixels") else set())
        flat = {**flat, "obs": {k: v for k, v in flat["obs"].items() if k in keys}}
        if self.array_type == "numpy":  # MuJoCo C's arrays are on the host already: no JAX on the cpu path
            flat = flat if self.backend == "cpu" else hand_off(flat, "numpy")
            return self._with_physics(self._view(flat, np), flat, np)
        if self._view_jit is None:
            import jax

            self._view_jit = jax.jit(lambda f: self._with_physics(self._view(f, _jnp()), f, _jnp()))
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
            "contained": flat["contained"],  # the block and the pusher never left the walls (no missed contact)
        }
        if "goal" in o:  # random goals: in info, and beside the T in state and keypoints (pixels draw the target there)
            info["goal_pose"] = o["goal"]
            if self.obs_type in ("state", "keypoints"):
                obs = with_goal(obs, o["goal"], self.obs_type)
        if xp is np:  # the host's convention, as the single env and SyncVectorEnv give them
            info = {k: np.asarray(v, np.float64 if np.asarray(v).dtype.kind == "f" else
                                  (bool if np.asarray(v).dtype == bool else np.int64)) for k, v in info.items()}
            out = (obs, np.asarray(flat["reward"], np.float64), np.asarray(flat["terminated"], bool),
                   np.asarray(flat["truncated"], bool))
        else:
            out = (obs, flat["reward"], flat["terminated"], flat["truncated"])
        return out + (info | {f"_{k}": every for k in info},)

    def _with_physics(self, out: tuple, flat: dict, xp) -> tuple:
        """`_view`'s outputs with each env's drawn physics in info["physics"] (envs/physics.info), masked as
        gymnasium's SyncVectorEnv masks a dict info; unchanged without `randomize`."""
        drawn = physics.info(self._env, flat.get("physics"), xp)
        if not drawn:
            return out
        every = xp.ones(self.num_envs, dtype=bool)
        values = drawn["physics"]
        if xp is np:  # the host's convention, as the other infos
            values = {k: np.asarray(v, np.float64) for k, v in values.items()}
        return out[:4] + ({**out[4], "physics": values | {f"_{k}": every for k in values}, "_physics": every},)

    def render(self):
        """One picture per environment, as a tuple (gymnasium's convention), drawn on the CPU renderer:
        about 4 ms each at 512 x 512 on this project's 2-core machine, so mind it for thousands of envs."""
        if self.render_mode != "rgb_array":
            return None
        validate.started(self._state, "render")
        qpos = self._state.data.qpos[-1] if self.backend == "cpu" else self._state.data.qpos
        return tuple(self._draw(qpos, self._state.carry.get("goal")))

    def close_extras(self, **kwargs):
        self._close_renderers()

    # gymnasium's vector API, as SyncVectorEnv offers it: one batch, so an attribute is the same for every env,
    # but render already answers per env (a frame each): call("render") hands those on, never the whole batch once
    # per env (500 envs were 500 x 500 frames to a client that rendered through `call`)
    def call(self, name: str, *args, **kwargs) -> tuple:
        """`name` called (or read, if not callable) on each sub-environment: one result per env, as SyncVectorEnv
        returns."""
        from mjx_pusht import boundary

        boundary.attribute(self, name)
        if name == "render":
            frames = self.render(*args, **kwargs)
            return (None,) * self.num_envs if frames is None else tuple(frames)
        attr = self._env.episode.max_steps if name == "_max_episode_steps" else getattr(self, name)
        value = attr(*args, **kwargs) if callable(attr) else attr
        return (value,) * self.num_envs

    @keywords  # a missing argument or an unknown keyword: one line naming what it takes
    def get_attr(self, name: str) -> tuple:
        return self.call(name)

    @keywords  # a missing argument or an unknown keyword: one line naming what it takes
    def set_attr(self, name: str, values) -> None:
        from mjx_pusht import boundary

        values = values if isinstance(values, (list, tuple)) else [values] * self.num_envs
        if len(values) != self.num_envs or not all(_same(v, values[0]) for v in values[1:]):
            raise ConfigError(f"the {self.num_envs} environments are one batch: set_attr needs one value for all")
        setattr(self, name, boundary.set_attr(self, name, values[0]))


def _same(a, b) -> bool:
    """Whether two set_attr values are one value (arrays compared whole, not as an ambiguous truth value)."""
    try:
        return a is b or bool(a == b)
    except (ValueError, TypeError):
        return np.array_equal(np.asarray(a), np.asarray(b))
