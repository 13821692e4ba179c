"""The functional env's `State`: one batch of episodes, every field an array over the batch (functional.py)."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from mjx_pusht.errors import ConfigError


class State(NamedTuple):
    """One batch of episodes. `data` is the backend's physics state; the rest is arrays."""

    data: Any  # mjx.Data (batched) or the CPU's MjData copies
    carry: dict  # episode.begin's carry: invariants, episode bookkeeping, end poses
    obs: dict  # {"state": (N, 5), "keypoints": (N, 16)}
    reward: Any  # (N,) coverage after the last step (0 for an ended episode)
    terminated: Any  # (N,) bool: coverage reached the success threshold
    truncated: Any  # (N,) bool: max_steps control steps taken without success
    step: Any  # (N,) int32 control steps taken
    key: Any  # (N, 2) uint32 seed words
    dropped: Any = None  # (N,) int32 MJX-Warp overflow bits since reset (0: nothing dropped); None on cpu/mjx-jax
    info: Any = None  # wrappers' own arrays (wrappers.AutoReset: the start pool, the ended episodes' outcome)
    physics: Any = None  # (N, k) each episode's physics factors, drawn from its seed (`randomize`); None: the scene's

    @property
    def metrics(self) -> dict:
        """coverage, best_coverage, return, success, steps_to_success, and the invariants."""
        ep, inv = self.carry["ep"], self.carry["inv"]
        return {k: ep[k] for k in ("coverage", "best_coverage", "return", "success", "steps_to_success")} | {
            "gap_max_dev": inv["gap_max_dev"], "finite": inv["finite"], "contained": inv["contained"]}


def check_state(value, backend: str, env=None, what: str = "step") -> None:
    """The functional env's `step` (and `reset_where`: `what`) takes the State its `reset` or `step` returned (None
    was an AttributeError), from an env of its own backend: a cpu State's worlds are MuJoCo C's, an MJX State's arrays
    (the other's was a raw TypeError or AttributeError deep in the step); of its own task and goal (`env`), as what
    it observes says (a chapter env stepped a gym-pusht State in the wrong frame: the tenth hostile pass)."""
    from mjx_pusht.boundary import _show

    if not isinstance(value, State):
        raise ConfigError(f"{what} takes the State that reset or step returned, got {_show(value)}")
    on_cpu = type(value.data).__module__ == "mjx_pusht.backends.cpu"
    if on_cpu != (backend == "cpu"):
        raise ConfigError(f"this PushTEnv runs on {backend}, but the State came from "
                          f"{'a cpu' if on_cpu else 'an MJX'} env's reset or step: step each env's own States")
    if env is not None and not _own_state(value, env):
        raise ConfigError(f"this PushTEnv is the {env.scene.variant} scene ({env.scene.break_it}, {env.scene.pusher} "
                          f"pusher) with {'random' if env.episode.goal else 'the fixed'} goal"
                          f"{' and drawn physics' if env.scenario.randomize else ''}, but the State came from an env "
                          "of another scene, task, goal or physics: step each env's own States")


def _own_state(state, env) -> bool:
    """Whether `state` is of `env`'s scene, task, goal and physics, by what it holds: its observation's keys
    (gym-pusht's pusher_vel, a random goal), its drawn physics, its worlds' model (MuJoCo C: the env's own one;
    MJX: its size; a capsule's MJX State is a cylinder's in shape, and passes)."""
    obs = state.obs if isinstance(state.obs, dict) else {}
    if (("pusher_vel" in obs) != (env.scene.variant == "gym-pusht") or ("goal" in obs) != (env.episode.goal is not None)
            or (state.physics is None) != (not env.scenario.randomize)):
        return False
    if env.backend == "cpu":
        models = getattr(state.data, "models", [])
        return bool(env.scenario.randomize) or not models or models[0] is env.model
    return np.shape(state.data.qpos)[-1:] == (env.model.nq,)
