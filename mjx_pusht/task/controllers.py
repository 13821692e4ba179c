"""What drives the pusher: controllers, written once for NumPy and JAX arrays.

A controller is pure: `act(carry, obs, t, key) -> (action, carry)`, where `obs` is the
observation dict of `task.observe` (`state` (..., 5), `keypoints` (..., 16)), `t` the
control step (0, 1, ...), `key` (..., 2) uint32 words of the episode's seed, and `carry`
whatever the controller keeps between steps (`init(key)` makes it). Every array has the
same leading batch shape: (N,) on the CPU backend, () per world under `jax.vmap` on MJX,
so the same code runs inside the compiled scan and on the host.

A user's controller is a plain function `policy(obs, t) -> action` named as
`package.module:function` (see `load`); it is wrapped as a stateless controller.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import math
import os
import threading
from collections.abc import Callable
from typing import ClassVar

import numpy as np

from mjx_pusht.task.controller_base import Controller, ControllerError
from mjx_pusht.task.expert_gym_pusht import ExpertGymPusht
from mjx_pusht.task.rules import (
    CTRL_LIMIT,
    T_REACH,
    array_namespace,
    distance_to_tee,
    wrap_angle,
)
from mjx_pusht.task.schedule import Schedule

BUILTIN = ("zero", "nudge", "random", "expert", "expert-gym-pusht")


def seed_key(seeds) -> np.ndarray:
    """(N, 2) uint32 words (low, high) of int64 seeds: the per-episode key every backend passes."""
    s = np.asarray(seeds, np.int64).astype(np.uint64)
    return np.stack([(s & np.uint64(0xFFFFFFFF)).astype(np.uint32), (s >> np.uint64(32)).astype(np.uint32)], axis=-1)


def _mix32(h, xp):
    """A 32-bit integer finaliser (lowbias32): every input bit flips about half the output bits."""
    h = h ^ (h >> 16)
    h = h * xp.asarray(0x7FEB352D, dtype=xp.uint32)
    h = h ^ (h >> 15)
    h = h * xp.asarray(0x846CA68B, dtype=xp.uint32)
    return h ^ (h >> 16)


def uniform_hash(key, t, lane: int):
    """A uniform draw in [0, 1) from (seed key, step, lane): counter-based, so identical in NumPy and JAX."""
    xp = array_namespace(key)
    t = xp.astype(xp.asarray(t), xp.uint32)
    salt = xp.asarray((0x9E3779B9 + lane) & 0xFFFFFFFF, dtype=xp.uint32)
    with np.errstate(over="ignore"):  # wrap-around is the point (uint32 arithmetic mod 2**32)
        h = _mix32(key[..., 0] ^ _mix32(key[..., 1] ^ _mix32(t * xp.asarray(2, dtype=xp.uint32) + salt, xp), xp), xp)
    return xp.astype(h >> 8, xp.float32) * (1.0 / (1 << 24))


@dataclasses.dataclass(frozen=True)
class Zero(Controller):
    """The pusher holds still: what the physics does on its own (nothing, once settled)."""

    def open_loop(self, steps: int, frame_skip: int) -> np.ndarray:
        return np.zeros((steps, 2))


@dataclasses.dataclass(frozen=True)
class Nudge(Controller):
    """The chapter's schedule: ctrl 0 for the settle steps, then the nudge velocity, by physics step."""

    name: str = "nudge"
    schedule: Schedule = Schedule()
    frame_skip: int = 1

    def act(self, carry, obs, t, key):
        xp = array_namespace(obs["state"])
        settling = t * self.frame_skip < self.schedule.settle_steps
        nudge = xp.asarray(self.schedule.nudge_ctrl, dtype=obs["state"].dtype)
        u = xp.where(settling, xp.zeros_like(nudge), nudge)
        return xp.broadcast_to(u, obs["state"].shape[:-1] + (2,)), carry

    def open_loop(self, steps: int, frame_skip: int) -> np.ndarray:
        k = np.arange(steps) * self.frame_skip
        return np.where((k < self.schedule.settle_steps)[:, None], 0.0, np.asarray(self.schedule.nudge_ctrl))


@dataclasses.dataclass(frozen=True)
class Random(Controller):
    """Uniform velocity commands in the ctrlrange, a fresh draw each control step, seeded by the episode."""

    name: str = "random"

    def act(self, carry, obs, t, key):
        xp = array_namespace(obs["state"])
        u = xp.stack([uniform_hash(key, t, 0), uniform_hash(key, t, 1)], axis=-1)
        return xp.astype(2.0 * u - 1.0, obs["state"].dtype) * CTRL_LIMIT, carry


# -- the expert ------------------------------------------------------------------------------------
# The scene's block is quasi-static with joint-level friction: x and y each resist with 1.2 N of
# frictionloss, yaw with only 0.006 N m, both about the bar centre (the tee's origin). So a push
# whose line passes through the origin translates the T without turning it, and a gentle push far
# from the origin (the stem's side, 8 cm out) turns it without translating it (under 1.2 N). The
# expert uses exactly those two moves: turn to the target yaw, then push along one body axis at a
# time through the origin, steering the yaw with a small lateral offset; between moves it walks
# the pusher around the T on a circle that clears it.
ROTATE, PUSH_X, PUSH_Y = 1, 2, 3
NEAR = 16  # carry bit: the T has come near the target (so it turns to yaw 0)
REVERSE = 32  # carry bit: travelling round the T the long way (a wall blocked the short way)
WALL_LIMIT = 0.37  # the pusher's centre stays inside this (walls' inner faces at 0.39, radius 0.015)

PUSHER_R = 0.015  # the cylinder's radius
PRE_GAP = 0.012  # a push starts this far from the face
ORBIT_R = T_REACH + PUSHER_R + 0.02  # pusher centre on this circle never touches the T
STEM_LEVER_Y = -0.08  # where a turning push meets the stem's side (body frame)


@dataclasses.dataclass(frozen=True)
class Expert(Controller):
    """A scripted closed-loop pusher that solves PushT: turn, then translate, then trim."""

    name: str = "expert"
    reads_goal: ClassVar[bool] = True  # pushes toward obs["goal"] when there is one
    yaw_enter: float = 0.15  # a push that drifts the yaw past this stops to turn
    yaw_done: float = 0.006  # a turn stops here
    pos_tol: float = 0.0007  # per body axis, m
    push_gain: float = 2.45  # extra m/s of push speed per m of error (~0.5 s time constant)
    push_min: float = 0.061  # the servo force at rest is 20 * u: 1.2 N of frictionloss needs u > 0.06
    push_max: float = 0.4
    turn_gain: float = 0.19  # m/s per rad (~0.5 s time constant)
    turn_min: float = 0.004  # 0.006 N m of yaw frictionloss at an 8 cm lever needs u > 0.0038
    turn_max: float = 0.25
    steer: float = 0.1  # m of lateral offset per rad of yaw error while translating
    travel_gain: float = 8.0  # 1/s, moving to the start of a push
    travel_max: float = 0.8
    travel_min: float = 0.0  # m/s: 0, the approach to a push slows in proportion to the distance left
    corridor: float = 0.15  # rad: within this polar angle of a push's start, go straight to it
    near: float = 0.06  # m: beyond this (either axis) the T travels square to the axes, then turns to 0
    wall_room: float = 0.2  # m: from here (fully at +4 cm) a stem toward the wall leaves no room behind it

    def act(self, mode, obs, t, key):
        xp = array_namespace(obs["state"])
        s = obs["state"]
        p, o, th = s[..., 0:2], s[..., 2:4], s[..., 4]
        c, sn = xp.cos(th), xp.sin(th)

        def to_body(v):
            return xp.stack([c * v[..., 0] + sn * v[..., 1], -sn * v[..., 0] + c * v[..., 1]], axis=-1)
        q = to_body(p - o)  # pusher, body frame
        # the T's offset from the goal and the yaw it ends at: an episode's own goal (task/goals.py) if it has one.
        # The walls stay where they are in the world, and the pushes along world x and y (the joints) stay so too.
        eo, yaw_goal = (o, 0.0) if "goal" not in obs else (o - obs["goal"][..., 0:2], obs["goal"][..., 2])
        # Far from the target the T is translated at the multiple of 90 degrees nearest its yaw (its
        # faces then meet world x and y square on), never with its stem toward a wall it must be
        # pushed away from (no room behind the stem); near the target it turns to yaw 0 itself.
        # (bit NEAR of the carry latches "near", so the boundary cannot flip the target back and forth)
        reach = xp.maximum(xp.abs(eo[..., 0]), xp.abs(eo[..., 1]))
        was_near = (mode & NEAR) != 0
        far = xp.where(was_near, reach > self.near + 0.04, reach > self.near)
        reverse = (mode & REVERSE) != 0
        mode = mode & (NEAR - 1)
        best, psi = None, xp.zeros_like(th)
        for k in range(4):
            psi_k = k * (math.pi / 2)
            stem_out = math.sin(psi_k) * o[..., 0] - math.cos(psi_k) * o[..., 1]  # stem direction . position
            # a ramp, not a step: a turn toward psi_k must not be undone by the few 0.1 mm it shifts the T
            cost = xp.abs(wrap_angle(th - psi_k)) + 10.0 * xp.clip((stem_out - self.wall_room) / 0.04, 0.0, 1.0)
            better = cost < best if best is not None else xp.ones_like(far)
            psi = xp.where(better, psi_k, psi)
            best = cost if best is None else xp.minimum(best, cost)
        eth = wrap_angle(xp.where(far, psi, yaw_goal) - th)
        # Translation errors in the world frame: x and y are separate joints, each with its own
        # 1.2 N of frictionloss, so a push along world x through the origin moves world x alone.
        ex, ey = xp.abs(eo[..., 0]), xp.abs(eo[..., 1])
        ae = xp.abs(eth)

        # which move: hysteresis so a move is finished before the next one starts
        placed = (ex < self.pos_tol) & (ey < self.pos_tol)
        turning = xp.where(mode == ROTATE, ae > self.yaw_done, ae > self.yaw_enter) | (placed & (ae > self.yaw_done))
        keep_x = (mode == PUSH_X) & (ex > self.pos_tol)
        keep_y = (mode == PUSH_Y) & (ey > self.pos_tol)
        axis = xp.where(keep_x, PUSH_X, xp.where(keep_y, PUSH_Y, xp.where(ex >= ey, PUSH_X, PUSH_Y)))
        mode = xp.where(turning, ROTATE, axis)

        # the push: contact point `cp` and push direction `n` in the body frame, speed `u`
        zero = xp.zeros_like(th)
        sth = xp.where(eth >= 0, 1.0, -1.0)
        lat = self.steer * eth
        # turn: CCW pushes the stem's left side toward +x, CW its right side toward -x
        rot_c = xp.stack([-sth * 0.015, zero + STEM_LEVER_Y], -1)
        rot_n = xp.stack([sth, zero], -1)
        rot_u = xp.clip(self.turn_min + self.turn_gain * ae, 0.0, self.turn_max)
        # translate: push along world x or y toward 0, at the face the push direction meets in the
        # body frame (+x_b: the bar's left end, -x_b: its right end, +y_b: the stem's bottom, -y_b:
        # the bar's top), where the push's line through the origin crosses that face, shifted by
        # `lat` to steer the yaw (the torque of a unit push at c along n is c_x n_y - c_y n_x)
        is_x = (mode == PUSH_X)[..., None]
        w = xp.where(is_x, xp.stack([xp.where(eo[..., 0] <= 0, 1.0, -1.0), zero], -1),
                     xp.stack([zero, xp.where(eo[..., 1] <= 0, 1.0, -1.0)], -1))
        nb = to_body(w)
        along_x = xp.abs(nb[..., 0]) >= xp.abs(nb[..., 1])
        gx, gy = xp.where(nb[..., 0] >= 0, 1.0, -1.0), xp.where(nb[..., 1] >= 0, 1.0, -1.0)
        end_x = -gx * 0.06
        end_c = xp.stack([end_x, xp.clip(end_x * nb[..., 1] / nb[..., 0] - gx * lat, -0.01, 0.01)], -1)
        face_y = xp.where(gy > 0, -0.105, 0.015)
        half = xp.where(gy > 0, 0.01, 0.045)
        side_c = xp.stack([xp.clip(face_y * nb[..., 0] / nb[..., 1] + gy * lat, -half, half), face_y], -1)
        tr_c = xp.where(along_x[..., None], end_c, side_c)
        is_rot = (mode == ROTATE)[..., None]
        cp = xp.where(is_rot, rot_c, tr_c)
        n = xp.where(is_rot, rot_n, nb)
        err = xp.where(mode == PUSH_X, ex, ey)
        push_u = xp.clip(self.push_min + self.push_gain * err, 0.0, self.push_max)
        u = xp.where(mode == ROTATE, rot_u, push_u)
        tan = xp.stack([-n[..., 1], n[..., 0]], -1)

        # where the pusher is relative to the push: along the push (a) and across it (l)
        rel = q - cp
        a = xp.sum(rel * n, axis=-1)
        l_ = xp.sum(rel * tan, axis=-1)
        in_lane = (xp.abs(l_) < 0.006) & (a > -(PUSHER_R + PRE_GAP + 0.01)) & (a < -PUSHER_R + 0.006)
        v_push = u[..., None] * n - 6.0 * l_[..., None] * tan

        # otherwise travel: straight to the push's start when it is in view, else around the T
        start = cp - (PUSHER_R + PRE_GAP) * n
        phi_q = xp.atan2(q[..., 1], q[..., 0])
        dphi = wrap_angle(xp.atan2(start[..., 1], start[..., 0]) - phi_q)
        # around the T: chase a waypoint ahead on the circle that clears it, kept inside the walls;
        # while still close to the T the waypoint is straight out, so the pusher never drags along it
        free = xp.clip((distance_to_tee(p, s[..., 2:5]) - PUSHER_R - 0.003) / 0.015, 0.0, 1.0)
        # (bit REVERSE: a wall cut the short way round, so go the long way until the push is in view)
        step = xp.where(reverse, -xp.where(dphi >= 0, 1.0, -1.0) * 0.6, xp.clip(dphi, -0.6, 0.6))
        ahead = phi_q + step * free
        waypoint = xp.stack([ORBIT_R * xp.cos(ahead), ORBIT_R * xp.sin(ahead)], -1)
        waypoint_w = o + xp.stack([c * waypoint[..., 0] - sn * waypoint[..., 1], sn * waypoint[..., 0] + c * waypoint[..., 1]], -1)
        inside = xp.clip(waypoint_w, -WALL_LIMIT, WALL_LIMIT)
        gap = inside - p
        blocked = (xp.max(xp.abs(inside - waypoint_w), axis=-1) > 0.01) & (xp.sqrt(xp.sum(gap * gap, axis=-1)) < 0.01)
        in_view = xp.abs(dphi) < self.corridor
        reverse = (reverse | blocked) & ~in_view & (xp.abs(dphi) < 0.8 * math.pi)  # past the far side: the short way again
        v_orbit = self.travel_gain * to_body(gap)
        v_straight = self.travel_gain * (start - q)
        v_travel = xp.where(in_view[..., None], v_straight, v_orbit)
        speed = xp.sqrt(xp.sum(v_travel * v_travel, axis=-1))
        v_travel = v_travel * xp.minimum(1.0, self.travel_max / xp.maximum(speed, 1e-9))[..., None]
        if self.travel_min > 0:  # drive into the push's lane at a pace, not ever slower toward its start
            v_travel = v_travel * xp.maximum(1.0, self.travel_min / xp.maximum(speed, 1e-9))[..., None]

        v = xp.where(in_lane[..., None], v_push, v_travel)
        world = xp.stack([c * v[..., 0] - sn * v[..., 1], sn * v[..., 0] + c * v[..., 1]], axis=-1)
        carry = xp.astype(mode, xp.int32) | xp.where(far, 0, NEAR) | xp.where(reverse, REVERSE, 0)
        return xp.clip(world, -CTRL_LIMIT, CTRL_LIMIT), xp.astype(carry, xp.int32)


class _HardExit(SystemExit):
    """os._exit(code) called by a user's controller, turned into a SystemExit while the controller runs."""


@contextlib.contextmanager
def _no_hard_exit():
    """While a user's controller runs, `os._exit` on this thread raises (SystemExit, said in one line) instead of
    ending the process: os._exit runs no handler, so a run ended silently with exit 0 and no table. Only the
    controller's own thread: another (the SIGTERM watcher) still ends the process. A controller holding its own
    reference (`from os import _exit`, taken at import) is out of reach: documented (docs/troubleshooting.md)."""
    real, me = os._exit, threading.get_ident()

    def hard_exit(code=0):
        if threading.get_ident() != me:
            real(code)
        raise _HardExit(code)

    os._exit = hard_exit
    try:
        yield
    finally:
        os._exit = real


@dataclasses.dataclass(frozen=True)
class FromFunction(Controller):
    """A user's `policy(obs, t) -> action`, stateless; `action_type` says what the action means."""

    fn: Callable | None = None

    def act(self, carry, obs, t, key):
        try:
            with _no_hard_exit():
                action = self.fn(obs, t)
        except ControllerError:
            raise
        except SystemExit as e:  # exit() inside a policy would end the run with its code and no word of why
            how = "os._exit" if isinstance(e, _HardExit) else "exit"
            raise ControllerError(f"controller {self.name} called {how}({e.code}): a controller returns actions; "
                                  "the run stopped here") from None
        except Exception as e:  # noqa: BLE001 - a user's bug, said in one line with what it was
            raise ControllerError(f"controller {self.name} raised {type(e).__name__}: {e}".splitlines()[0]) from None
        want = obs["state"].shape[:-1] + (2,)
        if isinstance(action, (list, tuple)):  # a list of [x, y] pairs of the right shape is an array of them
            try:
                action = np.asarray(action)
            except (ValueError, TypeError):  # ragged
                raise ControllerError(f"controller {self.name} returned a ragged list; expected an array of shape "
                                      f"{want}") from None
        shape = getattr(action, "shape", None)
        if shape is None or tuple(shape) != tuple(want):
            got = f"shape {tuple(shape)}" if shape is not None else f"a {type(action).__name__}"
            raise ControllerError(f"controller {self.name} returned an action of {got}; expected shape {want} "
                                  f"(the batch's leading shape, then 2)")
        kind = getattr(getattr(action, "dtype", None), "kind", "f")
        if kind not in "fiu":  # complex lost its imaginary part with a warning; bools became 0/1 velocities
            raise ControllerError(f"controller {self.name} returned actions of dtype {action.dtype}; actions are "
                                  "real numbers (velocities in m/s, or positions in m)")
        return action, carry


# Controllers of the form PREFIX:ARGUMENT that a layer above the task provides, by prefix (`register`): the
# training layer registers `policy` (train/controller.py, when mjx_pusht is imported), so the task knows no
# network and a trained policy is still one --controller spec among the others.
_LOADERS: dict[str, Callable[..., Controller]] = {}


def register(prefix: str, loader: Callable[..., Controller]) -> None:
    """Make `load("PREFIX:...")` return `loader(spec, action_type=...)`; a prefix registered before is replaced.
    A registered prefix is matched before a user's `package.module:function`."""
    _LOADERS[prefix] = loader


def load(spec: str, *, action_type: str | None = None, schedule: Schedule = Schedule(), frame_skip: int = 10) -> Controller:
    """A built-in controller by name, a registered `PREFIX:ARGUMENT` (a trained policy as `policy:PATH`), or a
    user's function as `package.module:function`."""
    if spec in BUILTIN:
        ctrl = {"zero": lambda: Zero(), "nudge": lambda: Nudge(schedule=schedule, frame_skip=frame_skip),
                "random": lambda: Random(), "expert": lambda: Expert(),
                "expert-gym-pusht": lambda: ExpertGymPusht()}[spec]()
        if action_type not in (None, ctrl.action_type):
            commands = {"velocity": "velocities", "position": "positions", "target": "targets"}[ctrl.action_type]
            raise ControllerError(f"the built-in controller {spec!r} commands {commands}; --action {action_type} is "
                                  "for your own controllers")
        return ctrl
    prefix = spec.partition(":")[0]
    if ":" in spec and prefix in _LOADERS:  # e.g. policy:PATH, a checkpoint written by `mjx-pusht train`
        return _LOADERS[prefix](spec, action_type=action_type)
    if ":" not in spec:
        raise ControllerError(f"unknown controller {spec!r}: choose from {', '.join(BUILTIN)}, or give your own as "
                              "package.module:function")
    module_name, _, attr = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except (Exception, SystemExit) as e:  # noqa: BLE001 - whatever the user's module raises (exit too), in one line
        raise ControllerError(f"controller {spec!r}: cannot import {module_name!r} ({type(e).__name__}: {e})") from None
    fn = getattr(module, attr, None)
    if not callable(fn):
        raise ControllerError(f"controller {spec!r}: {module_name!r} has no function {attr!r}")
    return FromFunction(name=spec, action_type=action_type or "velocity", fn=fn)


def describe(ctrl: Controller) -> str:
    return f"{ctrl.name} ({ctrl.action_type} actions)"

