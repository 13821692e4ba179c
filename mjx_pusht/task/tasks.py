"""The tasks: which PushT a run is on, as data the one control step reads.

A task names the scene variant it runs on, its reset (seed -> start), what an action means on that
scene, when an episode ends, and its expert. There are two, and an easy variant of gym-pusht's:

- `chapter`: this project's PushT, the chapter's scene (joint friction, velocity servos), its `task`
  start distribution (or the chapter's own `chapter` reset), an episode over at reset if it starts covered.
- `gym-pusht`: the task the field scores PushT on, gym-pusht 0.1.8's: the drop-in's scene (gym-pusht's
  pymunk physics in MJCF, model/gym_pusht_scene.py), gym-pusht's seed -> start, actions as targets
  tracked by its PD law, success at coverage 0.95, 300 control steps, and a start on the goal scored by
  the first step (as gym-pusht does).
- `gym-pusht-easy`: gym-pusht's task from the `easy` starts (task/reset.py: the tee a few cm and degrees off the
  target, the pusher beside it), which its expert solves in a few dozen steps: a trivial variant to debug a
  policy or a training set-up on (gym-pusht#18). The chapter's task takes the same starts as `--reset easy`.

Every backend runs either task through the same rollout; `eval --backend gym-pusht` runs the second in
gym-pusht itself. A controller written for velocities runs on gym-pusht's scene through `as_targets`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pusht import boundary
from mjx_pusht.errors import ConfigError
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.model.gym_pusht import KP, KV
from mjx_pusht.task.controller_base import Wrapper
from mjx_pusht.task.controllers import Controller
from mjx_pusht.task.expert_gym_pusht import CONTACTS
from mjx_pusht.task.memory import CHAPTER, CarryFormat
from mjx_pusht.task.rules import SUCCESS_COVERAGE, array_namespace, yaw_in_window

# s: a PD-tracked pusher (gym-pusht's law, kp 100, kv 20) moving at velocity v settles this far behind its target,
# so a velocity command v becomes the target pusher + LEAD v
LEAD = KV / KP
FRAME_PX = 512.0  # gym-pusht's action space: targets within its 512-pixel frame (the drop-in's TARGET_BOUNDS)


def lead_target(pusher, velocity):
    """The target pusher + LEAD v, kept in gym-pusht's frame as gym-pusht's action space keeps it (its backend and
    the drop-in clip every target so): unclipped, a policy's target far outside sent the pusher a metre off on the
    batch where gym-pusht stopped it at the frame's edge. A target inside is pusher + LEAD v to the bit."""
    xp = array_namespace(pusher)
    target = pusher + LEAD * xp.astype(xp.asarray(velocity), pusher.dtype)
    px = frame.to_px(target, xp)
    inside = xp.all((px >= 0.0) & (px <= FRAME_PX), axis=-1)
    return xp.where(inside[..., None], target, frame.to_world(xp.clip(px, 0.0, FRAME_PX), xp))


@dataclasses.dataclass(frozen=True)
class Task:
    name: str
    variant: str  # the scene variant (model/scene.VARIANTS)
    resets: tuple[str, ...]  # the start distributions it takes (task/reset.RESETS), its default first
    action_type: str  # what an action means on its scene (task/rules.ACTION_TYPES)
    expert: str  # the built-in controller that solves it (task/controllers.load)
    end_covered_start: bool  # a start already covered: over at reset (True), or scored by the first step
    success: float = SUCCESS_COVERAGE
    max_steps: int = 300
    frame_skip: int = 10
    about: str = ""
    memory: CarryFormat = CHAPTER  # how its expert's carry reads as a DAgger student's memory
    action_eps: float | None = None  # DAgger's --action-eps on this task by default (train/dagger_config.py DaggerConfig)
    # The yaw convention of its observations (the one place it is stated): a controller is handed the T's yaw in
    # (yaw_centre - pi, yaw_centre + pi], the window its starts fill, whatever the source gives (`observed`). The
    # chapter's starts turn the T anywhere in (-pi, pi]; gym-pusht draws its block angle in (-pi, pi) and a yaw is
    # pi/4 minus that angle, so its starts fill (pi/4 - pi, pi/4 + pi), while its observation wraps the angle to
    # [0, 2 pi): the same T at yaws 2 pi apart, one of them never seen in training.
    yaw_centre: float = 0.0

    @property
    def reset(self) -> str:
        return self.resets[0]

    def check_reset(self, reset: str | None) -> str:
        """The reset a run uses: `reset`, or the task's own when None; one the task does not take is an error."""
        if reset is None:
            return self.reset
        if reset not in self.resets:
            raise ConfigError(f"the {self.name} task starts from {' or '.join(self.resets)}, not reset {reset!r}")
        return reset

    def scene(self, break_it: str = "none"):
        from mjx_pusht.model.scene import SceneSpec

        return SceneSpec(break_it, variant=self.variant)

    def episode(self, max_steps: int | None = None, frame_skip: int | None = None,
                success_threshold: float | None = None, goal: str = "fixed"):
        """This task's episodes: its own length, frame skip and success coverage unless given (a threshold outside
        (0, 1] is a one-line error, Episode's check), toward the fixed goal or random ones (task/goals.py)."""
        from mjx_pusht.task.episode import Episode
        from mjx_pusht.task.goals import check, region

        return Episode(frame_skip=self.frame_skip if frame_skip is None else frame_skip,
                       max_steps=self.max_steps if max_steps is None else max_steps,
                       success=self.success if success_threshold is None else success_threshold,
                       end_covered_start=self.end_covered_start,
                       goal=region(self.variant) if check(goal) == "random" else None)

    def observed(self, state):
        """An observation state (..., 5: pusher x, y, tee x, y, yaw) with its yaw in this task's window."""
        xp = array_namespace(state)
        return xp.concat([state[..., :4], yaw_in_window(state[..., 4:5], self.yaw_centre)], axis=-1)

    def from_velocity(self, action, obs):
        """A velocity command as this task's scene takes it: itself, or (targets) the target that reaches it."""
        if self.action_type != "target":
            return action
        return lead_target(obs["state"][..., 0:2], action)

    def check_policy(self, ctrl, spec) -> None:
        """A trained policy (a controller with its checkpoint's `meta`) acts on the scene it was trained on: one of
        the chapter's pushed gym-pusht's (or back) would command the other scene's servos, without a word. Shared by
        every entry that takes a policy (eval, demos, GymPushtPolicy)."""
        meta = getattr(ctrl, "meta", None)
        if not isinstance(meta, dict):
            return
        trained = (meta.get("config") or {}).get("task") or "chapter"
        if trained not in TASKS or TASKS[trained].variant != self.variant:
            from mjx_pusht.task.controller_base import ControllerError

            raise ControllerError(f"{spec} was trained on the {trained} task, not {self.name}'s scene "
                                  f"(train --task {self.name}, or run it with --task {trained})")

    def controller(self, spec: str, *, action: str | None = None, frame_skip: int = 10, goal: str = "fixed") -> Controller:
        """The controller `spec` names (`expert`: this task's expert), commanding what this task's scene takes; for
        random goals, seeing the scene from each episode's goal (task/goals.GoalFrame) unless it reads obs["goal"]
        itself (`reads_goal`)."""
        from mjx_pusht.task.controllers import load
        from mjx_pusht.task.goals import check, in_goal_frame

        ctrl = load(self.expert if spec == "expert" else spec, action_type=action, frame_skip=frame_skip)
        self.check_policy(ctrl, spec)
        ctrl = as_targets(ctrl) if self.action_type == "target" and ctrl.action_type != "target" else ctrl
        if check(goal) != "random" or ctrl.reads_goal:
            return ctrl
        if ctrl.pixels:  # its image shows the world, the target at the goal: no frame turns a picture's target back
            raise ConfigError(f"{spec} looks at pixels and was made for the fixed goal: random goals need a controller "
                              "that reads obs['goal'] or one from state (seen from each goal's frame)")
        return in_goal_frame(ctrl)


TASKS = {
    "chapter": Task("chapter", "chapter", ("task", "chapter", "easy"), "velocity", "expert", end_covered_start=True,
                    about="this project's PushT: the chapter's scene and its task starts"),
    "gym-pusht": Task("gym-pusht", "gym-pusht", ("gym-pusht",), "target", "expert-gym-pusht", end_covered_start=False,
                      about="gym-pusht 0.1.8's PushT: its physics, starts, PD-tracked targets and success rule",
                      # its expert's carry: the contact it pursues, -1 before the first
                      memory=CarryFormat(moves=len(CONTACTS) + 1, latches=(), offset=1),
                      # its expert nudges the T home at 0.005-0.02 m/s: learned with the plain loss, 3 H100 students
                      # stood still short of it (91.2%, 94.6% held-out); with 0.01, 98.4-99.0% (notebook lead10)
                      action_eps=0.01, yaw_centre=frame.GOAL_PX[2]),
}
TASKS["gym-pusht-easy"] = dataclasses.replace(
    TASKS["gym-pusht"], name="gym-pusht-easy", resets=("easy",),
    about="gym-pusht's task from easy starts (the T a few cm off the target): its expert succeeds in a few dozen steps")


def get(name: str) -> Task:
    boundary.OneOf(tuple(TASKS))("task", name)  # an array is refused, not compared
    return TASKS[name]


@dataclasses.dataclass(frozen=True, eq=False)
class AsTargets(Wrapper):
    """A velocity (or position) controller on a scene whose pusher takes targets: a velocity v becomes the target
    pusher + LEAD v (`lead_target`: kept in gym-pusht's frame) that gym-pusht's PD law settles to moving at v; a
    position is the target itself."""

    action_type: str = "target"

    def act(self, carry, obs, t, key):
        action, carry = self.inner.act(carry, obs, t, key)
        if self.inner.action_type == "position":
            return action, carry
        with np.errstate(invalid="ignore", over="ignore"):  # a non-finite velocity is refused in one line, unwarned
            return lead_target(obs["state"][..., 0:2], action), carry


def as_targets(ctrl: Controller) -> Controller:
    return AsTargets(name=ctrl.name, inner=ctrl)


@dataclasses.dataclass(frozen=True, eq=False)
class AsVelocities(Wrapper):
    """A target controller read as velocities: the velocity (target - pusher) / LEAD that gym-pusht's PD law moves
    the pusher at toward the target (what a velocity-valued student is taught, train/dagger.py)."""

    action_type: str = "velocity"

    def act(self, carry, obs, t, key):
        target, carry = self.inner.act(carry, obs, t, key)
        return (target - obs["state"][..., 0:2]) / LEAD, carry


def as_velocities(ctrl: Controller) -> Controller:
    return AsVelocities(name=ctrl.name, inner=ctrl)
