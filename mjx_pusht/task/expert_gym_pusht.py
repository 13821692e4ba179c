"""An expert for gym-pusht's PushT task: a greedy pusher that plans with the block's exact push model.

gym-pusht's block (pymunk, 0.1.8) keeps no velocity between its 0.01 s steps (space.damping = 0), its
contacts are frictionless with restitution 0, and the agent is kinematic. So a push is an impulse j along
the face's inward normal n at the contact point r (from the centre of gravity) that stops the contact's
normal approach: the block moves exactly as far as the pusher advances along n, no further, as

    twist per pixel of push = (n, (r x n) / I) / (1 + (r x n)^2 / (m I)),  m = 1, I = 3000 px^2,

whatever the speed. The expert knows a fixed set of contacts (points on every face of the T, pushed along
the inward normal). Each control step it scores each contact by how fast it would reduce the pose error
(COG position and yaw, weighted): the push that best reduces the error along that contact's twist (a least-
squares length), divided by the time it would take (travelling round the T to the contact, then pushing).
It keeps pushing the contact it chose while that stays about as good (hysteresis), travels round the T on a
ring that clears its hull (the way round that the walls leave open) to reach a new one, and pushes by as
much as the model says is left, so the pushes shrink near the goal.

Written once for NumPy and jax.numpy (`xp`), branch-free on array values, fixed shapes: the same code runs
on the CPU backend's batch and per world inside MJX's jitted, vmapped scan. It reasons in gym-pusht's own
pixel frame (model/gym_pusht.py maps the observation there and the target back), where the walls are square.
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import numpy as np

from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.controller_base import Controller
from mjx_pusht.task.rules import array_namespace, distance_to_tee, wrap_angle

# The T in gym-pusht's body frame (pixels; origin the middle of the bar's top edge, the stem along +y).
COG = (0.0, frame.COG_PX)
MOMENT = 3000.0  # px^2 (mass 1): 2 * moment_for_poly(1, bar), about the COG
AGENT_R = frame.AGENT_RADIUS_PX
GOAL_ANGLE = frame.GOAL_PX[2]
GOAL_COG = (frame.GOAL_PX[0] - frame.COG_PX * math.sin(GOAL_ANGLE),
            frame.GOAL_PX[1] + frame.COG_PX * math.cos(GOAL_ANGLE))
LO, HI = frame.WALL_INNER_PX[0] + AGENT_R + 1.0, frame.WALL_INNER_PX[1] - AGENT_R - 1.0  # the agent's centre


def _contacts() -> np.ndarray:
    """(K, 4) contacts: a point on a face of the T and the inward normal a push there moves along (body frame).
    The points keep the agent clear of the faces beside them (its radius 15 from the stem on the bar's underside)."""
    out = [(x, 0.0, 0.0, 1.0) for x in (-55.0, -40.0, -20.0, 0.0, 20.0, 40.0, 55.0)]  # bar top, pushed stemwards
    for side in (-1.0, 1.0):
        out += [(60.0 * side, y, -side, 0.0) for y in (4.0, 15.0, 26.0)]  # bar ends
        out += [(x * side, 30.0, 0.0, -1.0) for x in (33.0, 45.0, 57.0)]  # bar underside
        out += [(15.0 * side, y, -side, 0.0) for y in (48.0, 65.0, 85.0, 100.0, 116.0)]  # stem sides
    out += [(x, 120.0, 0.0, -1.0) for x in (-12.0, 0.0, 12.0)]  # stem end
    return np.asarray(out, np.float64)


CONTACTS = _contacts()
# The T's convex hull's corners from the COG (body frame): its support bounds how far the T reaches at a bearing.
HULL = np.array([(-60.0, 0.0), (60.0, 0.0), (60.0, 30.0), (15.0, 120.0), (-15.0, 120.0), (-60.0, 30.0)]) - COG
RING = 32  # bearings about the COG at which the travel ring is checked against the walls


def _twists(contacts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per contact, the block's translation along n and its turn (rad) per pixel the agent pushes."""
    rx, ry = contacts[:, 0] - COG[0], contacts[:, 1] - COG[1]
    rxn = rx * contacts[:, 3] - ry * contacts[:, 2]
    k = 1.0 / (1.0 + rxn * rxn / MOMENT)
    return k, rxn / MOMENT * k


@dataclasses.dataclass(frozen=True)
class ExpertGymPusht(Controller):
    """Greedy model-based pusher for gym-pusht's task; actions are targets (gym-pusht's PD law tracks them)."""

    name: str = "expert-gym-pusht"
    action_type: str = "target"
    reads_goal: ClassVar[bool] = True  # pushes toward obs["goal"] when there is one
    turn_px: float = 60.0  # px of COG error one radian of yaw error weighs as
    gap: float = 8.0  # px: a push starts this far from its face
    margin: float = 8.0  # px: the travel ring's clearance beyond the agent's radius
    pass_gap: float = 5.0  # px: kept inside the walls, a ring point this near the T (the agent's edge) is passable
    orbit_step: float = 0.7  # rad: how far ahead on the ring the travel target lies
    corridor: float = 0.35  # rad: within this of the contact's bearing, go straight to the push's start
    travel_speed: float = 300.0  # px/s, for the time estimate of reaching a contact
    push_speed: float = 100.0  # px/s, for the time estimate of a push
    switch_s: float = 0.3  # s: the fixed cost of leaving one contact for another
    push_max: float = 150.0  # px: the longest push the linear model is trusted for
    push_gain: float = 0.6  # of the model's push length, led by the target each step
    lead_max: float = 25.0  # px: the target's lead over the contact (the PD law pushes at ~5 x lead px/s)
    stay: float = 1.5  # the current contact's rate counts this much more (hysteresis)
    lane: float = 5.0  # px: the agent is in a push's lane within this of its line

    def init(self, key):
        xp = array_namespace(key)
        return xp.full(key.shape[:-1], -1, dtype=xp.int32)

    def act(self, carry, obs, t, key):
        xp = array_namespace(obs["state"])
        s = obs["state"]
        dt = s.dtype
        p = frame.to_px(s[..., 0:2], xp)
        o, a = frame.pose_to_px(s[..., 2:5], xp)
        c, sn = xp.cos(a)[..., None], xp.sin(a)[..., None]

        def world(lx, ly):  # body-frame vectors (..., K) to pixel-frame x, y (..., K)
            return c * lx - sn * ly, sn * lx + c * ly

        cog_x = o[..., 0] - sn[..., 0] * COG[1]
        cog_y = o[..., 1] + c[..., 0] * COG[1]
        goal_x, goal_y, goal_a = GOAL_COG[0], GOAL_COG[1], GOAL_ANGLE
        if "goal" in obs:  # an episode's own goal (task/goals.py): its COG and angle in pixels, the walls as they are
            go, goal_a = frame.pose_to_px(obs["goal"], xp)
            goal_x, goal_y = go[..., 0] - xp.sin(goal_a) * COG[1], go[..., 1] + xp.cos(goal_a) * COG[1]
        err = xp.stack([goal_x - cog_x, goal_y - cog_y, self.turn_px * wrap_angle(goal_a - a)], -1)

        # each contact's twist per pixel pushed (world x, y, weighted yaw), and the push that best cuts the error
        kt, kw = (xp.asarray(v, dtype=dt) for v in _twists(CONTACTS))
        cx, cy, nx, ny = (xp.asarray(CONTACTS[:, i], dtype=dt) for i in range(4))
        nwx, nwy = world(nx, ny)
        tau = xp.stack([nwx * kt, nwy * kt, xp.broadcast_to(self.turn_px * kw, nwx.shape)], -1)  # (..., K, 3)
        proj = xp.sum(tau * err[..., None, :], axis=-1)
        length = xp.clip(proj / xp.sum(tau * tau, axis=-1), 0.0, self.push_max)
        gain = 2.0 * length * proj - length * length * xp.sum(tau * tau, axis=-1)  # the squared error it removes

        # where the agent touches each contact (its centre) and where a push there starts, in pixels
        tx, ty = world(cx - AGENT_R * nx, cy - AGENT_R * ny)
        touch_x, touch_y = o[..., 0:1] + tx, o[..., 1:2] + ty
        start_x, start_y = touch_x - self.gap * nwx, touch_y - self.gap * nwy
        inside = (start_x > LO) & (start_x < HI) & (start_y > LO) & (start_y < HI) & \
                 (touch_x > LO) & (touch_x < HI) & (touch_y > LO) & (touch_y < HI)

        # in a push's lane: on the line through its start and touch point, between them or just past the touch
        rel_x, rel_y = p[..., 0:1] - touch_x, p[..., 1:2] - touch_y
        along = rel_x * nwx + rel_y * nwy
        lateral = -rel_x * nwy + rel_y * nwx
        in_lane = (xp.abs(lateral) < self.lane) & (along > -(self.gap + 6.0)) & (along < 6.0)

        # Travel round the T on its hull: at bearing phi from the COG the agent keeps a distance of the T's support
        # there (its farthest extent along phi) plus its radius and a margin, so it cannot touch the T. A bearing
        # whose point cannot keep clear of the T inside the walls blocks the way; each contact is reached the
        # shorter unblocked way.
        qx, qy = p[..., 0] - cog_x, p[..., 1] - cog_y
        phi_q = xp.atan2(qy, qx)
        bx, by = start_x - cog_x[..., None], start_y - cog_y[..., None]
        phi_b = xp.atan2(by, bx)
        hx, hy = world(xp.asarray(HULL[:, 0], dtype=dt), xp.asarray(HULL[:, 1], dtype=dt))  # (..., 6) from the COG

        def ring(phi):  # the travel radius at bearings phi (..., M)
            ux, uy = xp.cos(phi)[..., None], xp.sin(phi)[..., None]
            return xp.max(hx[..., None, :] * ux + hy[..., None, :] * uy, axis=-1) + AGENT_R + self.margin

        grid = xp.asarray(np.arange(RING) * (2 * math.pi / RING), dtype=dt)
        rad = ring(xp.broadcast_to(grid, phi_q.shape + (RING,)))
        ring_px = xp.stack([cog_x[..., None] + rad * xp.cos(grid), cog_y[..., None] + rad * xp.sin(grid)], -1)
        ring_px = xp.clip(ring_px, LO, HI)
        # a bearing whose ring point, kept inside the walls, comes near the T: no way past the T there
        walled = distance_to_tee(frame.to_world(ring_px, xp), s[..., None, 2:5]) / frame.PX < AGENT_R + self.pass_gap
        # Which ring points lie on each way to each contact, leaving out those within 0.2 rad of the agent and
        # within the corridor of the contact (the way off and onto the ring): in bearings measured
        # counter-clockwise from the agent's, an interval each way. Counted with a prefix sum over the ring points
        # in that order, not per contact and point (that was 0.8 s a step at 4,096 episodes here).
        two_pi = 2 * math.pi
        step = two_pi / RING
        ccw = (phi_b - phi_q[..., None]) % two_pi  # (..., K): the counter-clockwise arc to each contact
        first = xp.astype(xp.ceil((phi_q % two_pi) / step), xp.int32)  # the first ring point at or past the agent
        offset = first * step - phi_q % two_pi  # its bearing from the agent's, in [0, step)
        order = (first[..., None] + xp.arange(RING)) % RING
        count = xp.cumulative_sum(xp.astype(xp.take_along_axis(walled, order, axis=-1), xp.int32), axis=-1,
                                  include_initial=True)  # (..., M + 1): walled points among the first j

        def walled_within(lo, hi):  # walled ring points at bearings in [lo, hi) from the agent's
            def below(x):
                return xp.clip(xp.astype(xp.ceil((x - offset[..., None]) / step), xp.int32), 0, RING)
            return xp.take_along_axis(count, below(hi), axis=-1) - xp.take_along_axis(count, below(lo), axis=-1) > 0

        block_ccw = walled_within(xp.maximum(0.2, ccw + self.corridor - two_pi), ccw - self.corridor)
        block_cw = walled_within(xp.maximum(0.2, ccw + self.corridor),
                                 xp.minimum(two_pi - 0.2, ccw - self.corridor + two_pi))
        go_ccw = ~block_ccw & (block_cw | (ccw <= math.pi))
        arc = xp.where(go_ccw, ccw, two_pi - ccw)
        in_view = xp.minimum(ccw, two_pi - ccw) < self.corridor
        direct = xp.sqrt((start_x - p[..., 0:1]) ** 2 + (start_y - p[..., 1:2]) ** 2)
        around = arc * 95.0 + 40.0  # px: the arc on a ring of ~95 px, and ~40 px onto it and off it
        reach = xp.where(in_view, direct, around) / self.travel_speed + self.switch_s
        k_now = xp.arange(CONTACTS.shape[0]) == carry[..., None]
        reach = xp.where(k_now & in_lane, 0.0, reach)
        rate = gain / (reach + length / self.push_speed + 0.1) * xp.where(k_now, self.stay, 1.0)
        rate = xp.where(inside & ~(block_ccw & block_cw & ~in_view), rate, -1.0)
        k = xp.argmax(rate, axis=-1)
        pick = xp.astype(xp.arange(CONTACTS.shape[0]) == k[..., None], dt)

        def chosen(v):
            return xp.sum(v * pick, axis=-1)

        n_x, n_y, t_x, t_y = chosen(nwx), chosen(nwy), chosen(touch_x), chosen(touch_y)
        st_x, st_y, lat, push = chosen(start_x), chosen(start_y), chosen(lateral), chosen(length)
        pushing = chosen(xp.astype(in_lane, dt)) > 0.5
        lead = xp.minimum(self.push_gain * push, self.lead_max)
        push_target = xp.stack([t_x + lead * n_x + lat * n_y, t_y + lead * n_y - lat * n_x], -1)

        # travel: straight to the push's start when in view, else chase a point ahead on the hull's ring; while
        # close to the T that point is straight out from the COG, so the agent never drags along a face
        view_k = chosen(xp.astype(in_view, dt)) > 0.5
        turn = xp.where(chosen(xp.astype(go_ccw, dt)) > 0.5, 1.0, -1.0) * xp.minimum(chosen(arc), self.orbit_step)
        gap_now = distance_to_tee(s[..., 0:2], s[..., 2:5]) / frame.PX - AGENT_R  # px between the agent and the T
        free = xp.clip((gap_now - 1.0) / (self.margin - 1.0), 0.0, 1.0)
        # (but where the walls cut the ring at the agent's own bearing, straight out is into a wall: go along)
        r_q = ring(phi_q[..., None])[..., 0]
        ring_q = xp.stack([cog_x + r_q * xp.cos(phi_q), cog_y + r_q * xp.sin(phi_q)], -1)
        free = xp.where(xp.any((ring_q < LO) | (ring_q > HI), axis=-1), 1.0, free)
        ahead = phi_q + turn * free
        r_ahead = ring(ahead[..., None])[..., 0]
        way = xp.stack([cog_x + r_ahead * xp.cos(ahead), cog_y + r_ahead * xp.sin(ahead)], -1)
        way = xp.clip(way, LO, HI)
        travel_target = xp.where(view_k[..., None], xp.stack([st_x, st_y], -1), way)
        target = xp.where(pushing[..., None], push_target, travel_target)
        return frame.to_world(target, xp), xp.astype(k, xp.int32)
