"""PushT as a Brax `Env`, so Brax's trainers run on it unchanged.

    from brax.training.agents.ppo import train as ppo
    env = BraxPushT(backend="mjx-warp", max_worlds=4096)
    make_policy, params, metrics = ppo.train(environment=env, num_envs=4096, episode_length=300, ...)

`reset(rng)` and `step(state, action)` are one world's, pure, as Brax expects (its VmapWrapper
batches them). The physics state (`State.pipeline_state`) is the functional env's State, and
`step` is its control step (`PushTEnv.step_one`), so an episode here is an episode of `eval`.

Start poses come from a table drawn ahead on the host (task seeds `first_seed` ..
`first_seed + table - 1`, reset.py), held on the device; `reset(rng)` picks a row of it.
`info["seed"]` says which seed an episode started from, so any episode can be replayed by
`eval`. `task` is the task's name (task/tasks.py): its scene, starts and episodes (the chapter's by default).
An action is a velocity (m/s, +-1 per axis) on either task, as a trained policy's is (train/policy.py): on
gym-pusht's, whose pusher takes targets, the target that moves it at that velocity (`Task.from_velocity`), as
`eval` drives the saved policy there. `randomize={name: (lo, hi)}` draws each table seed's physics as `eval --randomize` draws it
(model/randomize.py; held on the device beside the starts), its values in `info["physics"]`.
Brax's own AutoResetWrapper restarts a done env from that env's *first* state (every episode of an
env then starts the same); `wrap_for_training` is the same wrapper stack with a fresh start from the
table on every reset instead: pass it as `ppo.train(..., wrap_env_fn=...)`.

Episode ends reach Brax's trainer as the task defines them: success is a termination (no value
after it) and running out of control steps a truncation (`info["truncation"]`, which Brax's GAE
masks rather than bootstrapping a value of 0). Brax's EpisodeWrapper marks a truncation only where
the inner env is not already done, and this env's own step limit ends the episode on the same step,
so without `FreshStartAutoReset` setting it from the env's own `terminated` every time-out would
reach PPO as a termination: a free end to the per-step cost of failing.

On MJX-Warp the contact buffers are sized for `max_worlds` (the largest batch you will vmap,
training and evaluation envs alike) and every world's overflow bits are in
`metrics["dropped"]`: nonzero means a contact was dropped, and the numbers are not physics.
"""

from __future__ import annotations

import numpy as np

import jax
import jax.numpy as jnp

from mjx_pusht.errors import requires

with requires("the Brax adapter", "brax"):  # optional: say what to install, in one line
    from brax.envs.base import Env, State
    from brax.envs.wrappers import training as brax_training

from mjx_pusht import validate
from mjx_pusht.api import keywords
from mjx_pusht.backends import actions as action_check
from mjx_pusht.envs import physics as per_episode
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.errors import ConfigError


def _brax_compat() -> None:
    """Brax 0.14.2's trainers call `jax.device_put_replicated`, which JAX 0.10 removed from its public API
    (google/brax#671, open); the function itself is still in `jax._src.api`. Put it back where Brax looks,
    only if it is missing, so `ppo.train` runs unchanged."""
    from jax._src import api

    for name in ("device_put_replicated", "device_put_sharded"):
        deprecations = getattr(jax, "_deprecations", {})
        if name in deprecations and deprecations[name][1] is None and hasattr(api, name):
            deprecations[name] = (deprecations[name][0], getattr(api, name))


_brax_compat()
from mjx_pusht.task.controllers import seed_key
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.goals import with_goal
from mjx_pusht.task.reset import start_poses
from mjx_pusht.task.tasks import get as get_task

OBS_TYPES = ("state", "keypoints")


class BraxPushT(Env):
    """One PushT world as a Brax Env (state or keypoints observations; reward: coverage, or your `reward_fn`).
    `episode`: e.g. `tasks.get("chapter").episode(success_threshold=0.9, goal="random")`, random goals observed
    beside the T (task/goals.with_goal); None: the task's own. `reset_kind` None: the task's own starts."""

    def __init__(self, backend: str = "mjx-warp", obs_type: str = "state", reset_kind: str | None = None,
                 episode: Episode | None = None, max_worlds: int = 4096, table: int = 65536, first_seed: int = 0,
                 reward_fn=None, starts: np.ndarray | None = None, randomize=None, task: str = "chapter",
                 graph_mode: str | None = None):
        """`starts`: a (table, 5) array of starts (tee x, y, yaw, pusher x, y) to draw from instead of the task
        seeds' own (row i is still keyed and reported as seed `first_seed + i`). `graph_mode`: MJX-Warp's CUDA-graph
        mode (PushTEnv's; None: the env's default)."""
        if obs_type not in OBS_TYPES:
            raise ConfigError(f"the Brax adapter observes {' or '.join(OBS_TYPES)}, not {obs_type!r}")
        if backend == "cpu":
            raise ConfigError("Brax runs jitted JAX: use backend mjx-warp or mjx-jax (cpu is MuJoCo C on the host)")
        max_worlds, self.table = validate.positive_int("max_worlds", max_worlds), validate.positive_int("table", table)
        self.first_seed = validate.seed(first_seed, "first_seed")
        validate.seed(self.first_seed + self.table - 1, "first_seed + table - 1 (the table's last seed)")
        self.task = get_task(task)
        reset_kind = self.task.check_reset(reset_kind)
        self.env = PushTEnv(backend=backend, reset_kind=reset_kind, action_type=self.task.action_type,
                            episode=self.task.episode() if episode is None else episode, scene=self.task.scene(),
                            randomize=randomize, graph_mode=graph_mode)
        self.obs_type, self.reward_fn = obs_type, reward_fn
        seeds = np.arange(self.first_seed, self.first_seed + self.table, dtype=np.int64)
        if starts is None:
            starts = start_poses(seeds, reset=reset_kind)
        elif np.shape(starts) != (self.table, 5):
            raise ConfigError(f"starts must be ({self.table}, 5) (one row per table entry), got {np.shape(starts)}")
        else:
            starts = self.env.given_starts(starts)
        qpos = self.env.layout.initial_qpos(self.env.model, np.asarray(starts, np.float64))
        self._qpos = jnp.asarray(qpos, self.env.runner.dtype)
        self._keys = jnp.asarray(seed_key(seeds))
        f = per_episode.draw(self.env, seeds)  # each table seed's physics factors (None: the scene's own)
        self._physics = None if f is None else jnp.asarray(f, self.env.runner.dtype)
        self._d0 = self.env.template(int(max_worlds))

    def _brax(self, s, reward, pipeline_info: dict, metrics: dict | None = None) -> State:
        m = s.metrics
        # keep the keys wrappers added (Brax's EvalWrapper adds "reward"): a scan carries the same tree
        metrics = {**(metrics or {}), "coverage": m["coverage"], "success": m["success"].astype(jnp.float32)}
        if s.dropped is not None:
            metrics["dropped"] = s.dropped.astype(jnp.float32)
        if "bad_action" in pipeline_info:
            metrics["bad_action"] = (pipeline_info["bad_action"]["step"] >= 0).astype(jnp.float32)
        done = (s.terminated | s.truncated).astype(jnp.float32)
        obs = s.obs[self.obs_type]
        # the yaw in the task's window (Task.observed), as a PPO policy is handed it when it acts (train/policy.py)
        obs = self.task.observed(obs) if self.obs_type == "state" else obs
        obs = obs if "goal" not in s.obs else with_goal(obs, s.obs["goal"], self.obs_type)  # random goals: beside the T
        return State(pipeline_state=s, obs=obs, reward=reward, done=done, metrics=metrics, info=pipeline_info)

    def reset(self, rng: jax.Array) -> State:
        if not (isinstance(rng, jax.Array) or isinstance(rng, np.ndarray) and rng.dtype == np.uint32):
            # one key, as Brax's trainers hand it ('x' was JAX's own TypeError on key data: the eleventh pass)
            raise ConfigError(f"reset takes a JAX random key (jax.random.PRNGKey(seed)), got {type(rng).__name__}")
        i = jax.random.randint(rng, (), 0, self.table)
        s = self.env.fresh_one(self._d0, self._qpos[i], self._keys[i],
                               physics=None if self._physics is None else self._physics[i])
        info = {"seed": self.first_seed + i, "bad_action": action_check.record_init((), s.reward.dtype, jnp),
                **per_episode.info(self.env, s.physics, jnp)}
        return self._brax(s, jnp.zeros((), s.reward.dtype), info)

    def step(self, state: State, action: jax.Array) -> State:
        """One world's control step. A non-finite action never reaches the physics: called eagerly it is a
        `ConfigError` at once; inside jit it is zeroed and recorded per world (info["bad_action"]: the first
        such control step and value, metrics["bad_action"]: 1.0 from then on), and `check(state)` raises it
        on the host: a jitted program cannot raise, and a check per step would cost a round trip."""
        if tuple(jnp.shape(action)) != (2,):
            raise ConfigError(f"action must have shape (2,), one (x, y) for this world; got {tuple(jnp.shape(action))}")
        if not isinstance(action, jax.core.Tracer):
            validate.actions(np.asarray(action), (2,), -np.inf, np.inf)
        p = state.pipeline_state
        action, record = action_check.record_update(state.info["bad_action"], jnp.asarray(action), ~p.carry["ep"]["done"],
                                                    p.step, jnp)
        s = self.env.advance_one(p, self.task.from_velocity(action, p.obs))
        reward = s.reward if self.reward_fn is None else self.reward_fn(p, s)
        return self._brax(s, reward, {**state.info, "bad_action": record}, state.metrics)

    def check(self, state: State) -> State:
        """Raise a one-line `ConfigError` if any world of `state` (one or a batch) got a non-finite action since
        its reset, naming the world, its seed, the control step and the value; else return `state`."""
        if not isinstance(getattr(state, "info", None), dict) or "bad_action" not in state.info:
            # None, 'x', 5 were an AttributeError (the twelfth pass)
            raise ConfigError(f"check takes the State that reset or step returned, got {type(state).__name__}")
        step = np.atleast_1d(np.asarray(state.info["bad_action"]["step"]))
        rows = np.flatnonzero(step >= 0)
        if len(rows):
            r = rows[np.argmin(step[rows])]
            value = np.asarray(state.info["bad_action"]["value"]).reshape(-1, 2)[r].tolist()
            seed = int(np.atleast_1d(np.asarray(state.info["seed"]))[r])
            raise ConfigError(f"actions must be finite: world {r} (seed {seed}) got {value} at control step "
                              f"{int(step[r])}; {len(rows)} world(s) got one (zeroed before the physics)")
        return state

    @property
    def observation_size(self) -> int:
        return 5 if self.obs_type == "state" else 16

    @property
    def action_size(self) -> int:
        return 2

    @property
    def backend(self) -> str:
        return self.env.backend


# an unknown keyword (`BraxPushT(bogus=1)`: the tenth hostile pass): one line naming the known ones
BraxPushT.__init__ = keywords(BraxPushT.__init__)


class FreshStartAutoReset(brax_training.Wrapper):
    """Brax's AutoResetWrapper, but a done env restarts from a new start drawn from the table (a key per env), and
    `info["truncation"]` says which ends were time-outs: done and not terminated by the task (module docstring)."""

    def reset(self, rng: jax.Array) -> State:
        state = self.env.reset(rng)
        state.info["reset_key"] = jax.vmap(lambda k: jax.random.fold_in(k, 1))(rng) if rng.ndim > 1 else rng
        return state

    def step(self, state: State, action: jax.Array) -> State:
        if "steps" in state.info:
            state.info.update(steps=jnp.where(state.done, jnp.zeros_like(state.info["steps"]), state.info["steps"]))
        state = state.replace(done=jnp.zeros_like(state.done))
        state = self.env.step(state, action)
        keys = jax.vmap(jax.random.split)(state.info["reset_key"])
        fresh = self.env.reset(keys[:, 0])
        done = state.done

        def where_done(new, old):
            if not hasattr(new, "shape") or not new.shape or new.shape[0] != done.shape[0]:
                return old
            return jnp.where(done.reshape((-1,) + (1,) * (new.ndim - 1)) > 0, new, old)

        pipeline = state.pipeline_state
        truncation = jnp.where(done > 0, 1.0 - pipeline.terminated.astype(done.dtype), jnp.zeros_like(done))
        merged = jax.tree.map(where_done, fresh.pipeline_state._replace(data=None),
                              pipeline._replace(data=None))
        data = jax.vmap(lambda d, f, x: x.where(d > 0, f))(done, fresh.pipeline_state.data, pipeline.data)
        info = {**state.info, "reset_key": keys[:, 1], "truncation": truncation,
                "seed": jnp.where(done > 0, fresh.info["seed"], state.info["seed"])}
        if "physics" in info:  # the drawn physics of the episode each env now runs
            info["physics"] = jax.tree.map(where_done, fresh.info["physics"], state.info["physics"])
        return state.replace(pipeline_state=merged._replace(data=data), obs=where_done(fresh.obs, state.obs),
                             info=info)


def wrap_for_training(env: Env, episode_length: int = 300, action_repeat: int = 1, randomization_fn=None):
    """Brax's `training.wrap` with fresh starts on every reset (pass as `ppo.train(wrap_env_fn=...)`)."""
    if randomization_fn is not None:
        raise ConfigError("domain randomisation is not supported by the PushT Brax adapter")
    env = brax_training.VmapWrapper(env)
    env = brax_training.EpisodeWrapper(env, episode_length, action_repeat)
    return FreshStartAutoReset(env)
