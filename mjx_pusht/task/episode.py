"""One rollout, whatever steps the physics: observe, act, step `frame_skip` times, fold in the invariants and the reward.

These functions are the body of every backend's rollout. They take the backend's arrays
(NumPy batches on the CPU, one world's JAX arrays inside MJX's vmapped scan) and never know
which backend called them; the backends only differ in how they step MuJoCo.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht.task.goals import draw
from mjx_pusht.task.invariants import invariants_fold, invariants_init, invariants_update
from mjx_pusht.task.rules import (
    SUCCESS_COVERAGE,
    all_live,
    coverage,
    episode_init,
    episode_update,
    observe,
    to_ctrl,
)


@dataclasses.dataclass(frozen=True)
class Episode:
    """How long a rollout runs and when it ends.

    `frame_skip` physics steps per control step (10: 100 Hz physics, 10 Hz control, as gym-pusht
    and Diffusion Policy run), `max_steps` control steps at most (the truncation), and whether
    reaching `success` coverage ends the episode (a study of a fixed schedule runs to the end).
    """

    frame_skip: int = 10
    max_steps: int = 300
    terminate: bool = True
    success: float = SUCCESS_COVERAGE
    # A start that is already covered: over at reset (this project's rule: nothing left to do), or,
    # as gym-pusht does, run until its first step scores it (reward 1, terminated).
    end_covered_start: bool = True
    # Random goals: the region they are drawn in (task/goals.region, from the scene's walls); None: the fixed target.
    goal: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        from mjx_pusht import validate

        validate.steps("frame_skip", self.frame_skip, validate.MAX_FRAME_SKIP)
        # an env's own episodes may run to the int32 step counters' end (envs.common.NEVER: gymnasium's TimeLimit
        # truncates); a backend's rollout is a scan of max_steps, bounded by Scenario at validate.MAX_STEPS
        validate.steps("max_steps", self.max_steps, 2**31 - 1)
        validate.fraction("success_threshold", self.success)  # NaN never ends an episode, 2.0 never succeeds, 0 always does
        if self.goal is not None:  # a region of 7 finite numbers (goals.region); 'x' failed at the first step
            from mjx_pusht import boundary

            object.__setattr__(self, "goal", tuple(boundary.Array((7,))("Episode's goal region (goals.region)",
                                                                       self.goal).tolist()))

    @property
    def physics_steps(self) -> int:
        return self.frame_skip * self.max_steps


def _where(xp, cond, old, new):
    """Per-row select over a dict of arrays: rows where `cond` holds keep `old`."""
    out = {}
    for k in new:
        c = cond
        while c.ndim < new[k].ndim:
            c = c[..., None]
        out[k] = xp.where(c, old[k], new[k])
    return out


def begin(layout, qpos0, key, controller, episode: Episode, xp, coverage0=None):
    """The rollout's carry at reset: invariants, episode bookkeeping, the controller's state, the poses at the end.
    `coverage0`: the start's coverage, when already known (an autoreset pool computes it once, ahead). With random
    goals (`episode.goal`) the episode draws its goal from its key here (task/goals.py), carries it, observes it and
    is scored against it; a fixed goal carries nothing (the episodes of before goals, to the bit)."""
    tee = layout.tee_pose(qpos0)
    n = tee.shape[:-1]
    acc = invariants_init(n[0] if n else 1, xp)
    if not n:  # one world (under vmap): drop the batch axis invariants_init adds
        acc = {k: v[0] for k, v in acc.items()}
    acc = {k: (xp.astype(v, qpos0.dtype) if v.dtype != xp.bool else v) for k, v in acc.items()}
    target = () if episode.goal is None else (draw(key, episode.goal, tee.dtype),)
    carry = {
        "inv": acc,
        "ep": episode_init(coverage(tee, *target) if coverage0 is None else xp.astype(coverage0, tee.dtype),
                           episode.success, episode.terminate and episode.end_covered_start, xp),
        "ctrl": controller.init(key),
        "final": tee,
        "pusher_final": layout.pusher_xy(qpos0),
    }
    return {**carry, "goal": target[0]} if target else carry


def goal_of(carry) -> tuple:
    """The episode's goal as `coverage`'s target argument: (goal,), or () for the fixed target."""
    return (carry["goal"],) if "goal" in carry else ()


def act(carry, qpos, k, key, controller, layout, xp, image=None):
    """A controller's action for control step k from the observation of `qpos` (and `image`, the top camera's
    view of it, for a controller that looks: `controller.pixels`), and its next state."""
    obs = observe(layout.pusher_xy(qpos), layout.tee_pose(qpos))
    if "goal" in carry:
        obs["goal"] = carry["goal"]
    if image is not None:
        obs["pixels"] = image
    action, cstate = controller.act(carry["ctrl"], obs, k, key)
    return action, {**carry, "ctrl": cstate}


def control_step(sim, carry, qpos, k, action, action_type: str, physics, layout, episode: Episode, xp):
    """The control step, the only one: every rollout and the environment call this.

    The action becomes servo ctrl (`rules.to_ctrl`; an ended episode's pusher gets 0),
    `physics(sim, u, carry, k)` runs the backend's `frame_skip` physics steps, folding each
    into the invariants (`after_physics_step`), and returns (qpos after, carry, sim); then
    the step is scored (`after_control_step`). `sim` is the backend's own state (MjData
    copies, an mjx.Data), passed through untouched. Returns (qpos, carry, sim).
    """
    u = to_ctrl(xp.astype(xp.asarray(action), qpos.dtype), layout.pusher_xy(qpos), action_type)
    if not all_live(carry["ep"]["done"]):  # (on the host with every row live, the select would keep u)
        u = xp.where(carry["ep"]["done"][..., None], 0.0, u)
    qpos, carry, sim = physics(sim, u, carry, k)
    return qpos, after_control_step(carry, k, layout, qpos, episode, xp), sim


def after_physics_step(carry, t, settle_step, layout, qpos, qvel, sensordata, xp):
    """Fold physics step t into the invariants; an episode that has ended stops changing them."""
    acc = invariants_update(carry["inv"], t, settle_step, layout.tee_pose(qpos), layout.pusher_xy(qpos), qpos, qvel,
                            sensordata[..., 0:3], sensordata[..., 3:6])
    return {**carry, "inv": _where(xp, carry["ep"]["done"], carry["inv"], acc)}


def after_physics_steps(carry, t, settle_step, layout, qpos, qvel, sensordata, xp):
    """`after_physics_step` over a leading axis of consecutive steps at once (`t` (S,) or (S, N)): the same
    values to the bit, in a few array operations (the CPU's frame_skip steps of a control step)."""
    acc = invariants_fold(carry["inv"], t, settle_step, layout.tee_pose(qpos), layout.pusher_xy(qpos), qpos, qvel,
                          sensordata[..., 0:3], sensordata[..., 3:6])
    done = carry["ep"]["done"]
    skip = isinstance(done, np.ndarray) and not done.any()  # on the host, no ended row: nothing to keep
    return {**carry, "inv": acc if skip else _where(xp, done, carry["inv"], acc)}


def after_control_step(carry, k, layout, qpos, episode: Episode, xp):
    """Score control step k: reward = coverage after it; the episode's end state is kept while it runs."""
    tee = layout.tee_pose(qpos)
    live = ~carry["ep"]["done"]
    if not episode.terminate:
        # A study of a fixed schedule (the sweep) is scored once, from its final pose, on the host:
        # no coverage per step inside its 160-step scan.
        return {**carry, "final": tee, "pusher_final": layout.pusher_xy(qpos)}
    ep = episode_update(carry["ep"], coverage(tee, *goal_of(carry)), k, episode.success, episode.terminate)
    if all_live(carry["ep"]["done"]):  # every row live: the selects below would pick the new poses
        return {**carry, "ep": ep, "final": tee, "pusher_final": layout.pusher_xy(qpos)}
    return {
        **carry,
        "ep": ep,
        "final": xp.where(live[..., None], tee, carry["final"]),
        "pusher_final": xp.where(live[..., None], layout.pusher_xy(qpos), carry["pusher_final"]),
    }
