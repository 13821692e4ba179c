"""The PushT task, written once for NumPy and JAX arrays: observations, actions, coverage, reward, termination.

Every function here takes arrays with any leading batch shape and reads its array
namespace from its input (`x.__array_namespace__()`), so the CPU backend calls it on
(N, ...) NumPy batches and the MJX backends call it per world inside a vmapped,
jitted scan. There is one definition of what the task is, whatever steps the physics.

Conventions (metres, radians, world frame, z up, the target T at the origin with yaw 0):
- observation `state` = [pusher x, pusher y, tee x, tee y, tee yaw]; the tee's (x, y)
  is its body origin, the centre of the bar, which is also the point it yaws about;
- observation `keypoints` = the T's 8 outline corners in the world frame, (x, y) each,
  counter-clockwise from the bar's top-left corner (16 values);
- action `velocity` = the pusher servos' own ctrl, m/s, clipped to the ctrlrange [-1, 1];
- action `position` = a target (x, y) for the pusher, tracked by the velocity command
  `POSITION_GAIN * (target - pusher)`, clipped to the ctrlrange (gym-pusht's convention
  of commanding positions, here on velocity servos);
- action `target` = a target (x, y) for the pusher, in metres, handed to the gym-pusht
  scene's position servos as it is: gym-pusht's own PD law (model/gym_pusht.py);
- reward = coverage of the target T by the block T, in [0, 1]; an episode terminates
  at coverage >= `SUCCESS_COVERAGE` and is truncated after `max_steps` control steps.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from mjx_pusht.errors import ConfigError

# The T in its own frame (origin = bar centre): bar and stem as (centre_x, centre_y, half_x, half_y),
# from the scene's geoms (scene.TEE_WELDED_MJCF).
T_RECTS = ((0.0, 0.0, 0.06, 0.015), (0.0, -0.06, 0.015, 0.045))
T_AREA = sum(4 * hx * hy for _, _, hx, hy in T_RECTS)
# The outline, counter-clockwise from the bar's top-left corner.
T_OUTLINE = (
    (-0.06, 0.015), (-0.06, -0.015), (-0.015, -0.015), (-0.015, -0.105),
    (0.015, -0.105), (0.015, -0.015), (0.06, -0.015), (0.06, 0.015),
)
# Every point of a T lies within this distance of its origin (the stem's far corners).
T_REACH = max(math.hypot(abs(cx) + hx, abs(cy) + hy) for cx, cy, hx, hy in T_RECTS)
TARGET_POSE = (0.0, 0.0, 0.0)
SUCCESS_COVERAGE = 0.95
CTRL_LIMIT = 1.0  # the servos' ctrlrange, m/s (scene.ACTUATOR_MJCF)
POSITION_GAIN = 10.0  # 1/s: a position action closes 63% of its error in one 0.1 s control step
ACTION_TYPES = ("velocity", "position", "target")  # target: the gym-pusht scene only (its servos take positions)
OBS_TYPES = ("state", "keypoints")
STATE_DIM = 5
KEYPOINTS_DIM = 16


WORKSPACE_HALF = 0.39  # the walls' inner faces, m


def array_namespace(a):
    """NumPy or jax.numpy, whichever `a` belongs to: the task is written once for both."""
    return a.__array_namespace__()


def to_pixels(xy, size: int = 512):
    """World (x, y) in metres to pixel (column, row) on a size x size image of the walled workspace,
    rows downward: gym-pusht's 512-pixel frame when size is 512 (0.78 m / 512 px = 1.52 mm a pixel)."""
    xp = array_namespace(xy)
    scale = size / (2 * WORKSPACE_HALF)
    return xp.stack([(xy[..., 0] + WORKSPACE_HALF) * scale, (WORKSPACE_HALF - xy[..., 1]) * scale], axis=-1)


def from_pixels(px, size: int = 512):
    """Pixel (column, row) on the size x size workspace image back to world (x, y) in metres."""
    xp = array_namespace(px)
    scale = (2 * WORKSPACE_HALF) / size
    return xp.stack([px[..., 0] * scale - WORKSPACE_HALF, WORKSPACE_HALF - px[..., 1] * scale], axis=-1)


def wrap_angle(a):
    """Wrap to (-pi, pi]."""
    xp = array_namespace(a)
    w = (a + math.pi) % (2 * math.pi) - math.pi
    return xp.where(w == -math.pi, math.pi, w)


def yaw_in_window(yaw, centre: float):
    """A yaw given in any convention (a hinge's unwrapped turns, gym-pusht's [0, 2 pi), (-pi, pi]) as the one angle
    in (centre - pi, centre + pi] that points the same way: a task's observations are given in the window centred on
    its starts' yaws (task/tasks.py `Task.yaw_centre`), so a policy that reads the raw yaw sees what it trained on
    whichever convention its input arrived in."""
    return centre + wrap_angle(yaw - centre)


def rotate(pose, local):
    """Points given in a T's frame placed at `pose` (..., 3): (..., K, 2) world points from (K, 2) local ones."""
    xp = array_namespace(pose)
    c, s = xp.cos(pose[..., 2])[..., None], xp.sin(pose[..., 2])[..., None]
    lx, ly = local[:, 0], local[:, 1]
    return xp.stack([c * lx - s * ly + pose[..., 0:1], s * lx + c * ly + pose[..., 1:2]], axis=-1)


def distance_to_tee(points, pose):
    """Distance from (..., 2) world points to the T at (..., 3) poses (0 inside it)."""
    xp = array_namespace(pose)
    c, s = xp.cos(pose[..., 2]), xp.sin(pose[..., 2])
    dx, dy = points[..., 0] - pose[..., 0], points[..., 1] - pose[..., 1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    out = None
    for cx, cy, hx, hy in T_RECTS:
        ox = xp.maximum(xp.abs(lx - cx) - hx, 0.0)
        oy = xp.maximum(xp.abs(ly - cy) - hy, 0.0)
        d = xp.sqrt(ox * ox + oy * oy)
        out = d if out is None else xp.minimum(out, d)
    return out


def keypoints(pose):
    """(..., 16) the T's outline corners in the world frame, from (..., 3) tee poses."""
    xp = array_namespace(pose)
    pts = rotate(pose, xp.asarray(T_OUTLINE, dtype=pose.dtype))
    return xp.reshape(pts, pts.shape[:-2] + (KEYPOINTS_DIM,))


def observe(pusher_xy, tee_pose, with_keypoints: bool = True) -> dict:
    """The observation dict every controller receives: `state` (..., 5) and `keypoints` (..., 16) (left out
    with `with_keypoints=False`, for an env whose observations never show them)."""
    xp = array_namespace(tee_pose)
    obs = {"state": xp.concat([pusher_xy, tee_pose], axis=-1)}
    if with_keypoints:
        obs["keypoints"] = keypoints(tee_pose)
    return obs


def to_ctrl(action, pusher_xy, action_type: str):
    """Servo ctrl (..., 2) from an action: velocity as given, or a position target tracked proportionally."""
    xp = array_namespace(action)
    if action_type == "target":
        # the servos track the target themselves; a non-finite target holds the pusher where it is
        return xp.where(xp.isfinite(action), action, pusher_xy)
    if action_type == "velocity":
        u = action
    elif action_type == "position":
        u = POSITION_GAIN * (action - pusher_xy)
    else:
        raise ConfigError(f"unknown action type {action_type!r}; choose from {', '.join(ACTION_TYPES)}")
    # NaN from a broken policy becomes 0, not a NaN ctrl that would poison the physics silently
    u = xp.where(xp.isfinite(u), u, 0.0)
    # clip as minimum(maximum()): what np.clip and jnp.clip compute, without np.clip's checks (a third of the cost)
    return xp.minimum(xp.maximum(u, -CTRL_LIMIT), CTRL_LIMIT)


# -- coverage: exact area of (block T intersect target T) over the T's area ----------------------
# A T is two disjoint rectangles, so the overlap of two Ts is the sum of four convex rectangle
# intersections. Each is a Sutherland-Hodgman clip kept in a fixed 8-vertex buffer (a rectangle
# clipped by 4 half-planes has at most 8 vertices), branch-free so it traces under jit and vmap.
_SLOTS = 8


def _next_index(n, xp):
    i = xp.arange(_SLOTS)
    return xp.where(i + 1 < n[..., None], i + 1, 0)


def _take(pts, idx, xp):
    return xp.take_along_axis(pts, xp.stack([idx, idx], axis=-1), axis=-2)


def _clip(pts, n, a, b):
    """Clip polygons (..., 8, 2) with n valid vertices by the half-plane left of edge a->b."""
    xp = array_namespace(pts)
    valid = xp.arange(_SLOTS) < n[..., None]
    q = _take(pts, _next_index(n, xp), xp)
    ex, ey = (b - a)[..., None, 0], (b - a)[..., None, 1]

    def side(p):
        return ex * (p[..., 1] - a[..., None, 1]) - ey * (p[..., 0] - a[..., None, 0])

    sp, sq = side(pts), side(q)
    keep = (sp >= 0) & valid
    crosses = ((sp >= 0) != (sq >= 0)) & valid
    denom = sp - sq
    t = sp / xp.where(denom == 0, 1.0, denom)
    cut = pts + t[..., None] * (q - pts)
    # candidates in order: vertex i (if kept), then edge i's crossing (if any)
    cand = xp.reshape(xp.stack([pts, cut], axis=-2), pts.shape[:-2] + (2 * _SLOTS, 2))
    emit = xp.reshape(xp.stack([keep, crosses], axis=-1), keep.shape[:-1] + (2 * _SLOTS,))
    # compact the emitted candidates to the front, in order: a stable sort of "not emitted"
    src = xp.argsort(xp.astype(~emit, xp.int32), axis=-1, stable=True)[..., :_SLOTS]
    out = _take(cand, src, xp)
    return out, xp.sum(xp.astype(emit, xp.int32), axis=-1)


def _area(pts, n):
    xp = array_namespace(pts)
    q = _take(pts, _next_index(n, xp), xp)
    cross = pts[..., 0] * q[..., 1] - q[..., 0] * pts[..., 1]
    return 0.5 * xp.abs(xp.sum(xp.where(xp.arange(_SLOTS) < n[..., None], cross, 0.0), axis=-1))


def _rect_corners(pose, rect):
    xp = array_namespace(pose)
    cx, cy, hx, hy = rect
    local = xp.asarray([[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy], [cx - hx, cy + hy]], dtype=pose.dtype)
    return rotate(pose, local)


def _overlap(subject, clipper):
    """Area of convex quads (..., 4, 2) clipped by convex quads (..., 4, 2), counter-clockwise."""
    xp = array_namespace(subject)
    pts = xp.concat([subject, xp.zeros(subject.shape[:-2] + (_SLOTS - 4, 2), dtype=subject.dtype)], axis=-2)
    n = xp.full(subject.shape[:-2], 4, dtype=xp.int32)
    for k in range(4):
        pts, n = _clip(pts, n, clipper[..., k, :], clipper[..., (k + 1) % 4, :])
    return _area(pts, n)


def coverage(pose, target=TARGET_POSE):
    """Fraction of the target T's area covered by the block T at (..., 3) poses, in [0, 1]."""
    if isinstance(pose, np.ndarray) and pose.ndim == 2 and pose.dtype == np.float64:
        if len(pose) <= _FEW:  # one env's step: plain floats, no array calls (the same bits)
            return _coverage_few(pose, target)
        return coverage_np(pose, target)  # on the host: skip the poses too far away to overlap (exact)
    return _coverage(pose, target)


_FEW = 4  # up to this many host poses, `_coverage_few` (about 20x faster than the array code for one pose)


def _coverage_few(pose, target=TARGET_POSE) -> np.ndarray:
    """`coverage` of a few host poses in plain Python floats: the array code's operations, one by one, in its
    order (its 8-slot sum is NumPy's pairwise sum), so the same bits (test: against `coverage_np`)."""
    out = np.zeros(len(pose))
    tgts = [_target_few(tuple(target))] * len(pose) if np.ndim(target) == 1 else [
        _target_few(tuple(t)) for t in np.broadcast_to(np.asarray(target, np.float64), pose.shape).tolist()]
    rows = pose.tolist()
    if all(math.hypot(x - g[0][0], y - g[0][1]) >= 2 * T_REACH for (x, y, _), g in zip(rows, tgts)):
        return out  # every pose too far away to overlap (below): no cos/sin to compute
    cos, sin = np.cos(pose[:, 2]).tolist(), np.sin(pose[:, 2]).tolist()  # NumPy's cos/sin, as the array code's
    for i, (x, y, _) in enumerate(rows):
        out[i] = _cover(x, y, cos[i], sin[i], tgts[i])
    return out


def coverage_one(x: float, y: float, yaw: float) -> float:
    """`coverage` of one host pose at the target, from floats to a float: `_coverage_few`'s computation for
    one row (the gymnasium single env's step), without its array in and out."""
    tgt = _target_few(TARGET_POSE)
    if math.hypot(x - tgt[0][0], y - tgt[0][1]) >= 2 * T_REACH:
        return 0.0
    return _cover(x, y, float(np.cos(yaw)), float(np.sin(yaw)), tgt)


def _cover(x, y, c, s, tgt) -> float:
    """One pose's coverage of one target (`_target_few`), its yaw's cos and sin given."""
    (gx, gy), quads = tgt
    if math.hypot(x - gx, y - gy) >= 2 * T_REACH:
        return 0.0  # too far apart to overlap (coverage_np's exact shortcut)
    area = [_overlap_few(_corners_few(x, y, c, s, ra), quad)
            if math.hypot(c * ra[0] - s * ra[1] + x - centre[0], s * ra[0] + c * ra[1] + y - centre[1]) < reach
            else 0.0  # the rectangles' circumcircles (widened by 1 um) apart: their overlap is exactly 0
            for ra in T_RECTS for (quad, centre, reach) in
            ((q, cen, math.hypot(ra[2], ra[3]) + r) for q, cen, r in quads)]
    return min(max((((area[0] + area[1]) + area[2]) + area[3]) / T_AREA, 0.0), 1.0)


@functools.lru_cache(maxsize=64)
def _target_few(target: tuple):
    """A target pose's origin and its two rectangles' corners, centres and reach (+1 um), as `_coverage_few`
    uses them (NumPy's cos/sin of its yaw, as the array code's)."""
    gx, gy, yaw = (float(v) for v in target)
    tc, ts = float(np.cos(np.array([yaw]))[0]), float(np.sin(np.array([yaw]))[0])
    return (gx, gy), [(_corners_few(gx, gy, tc, ts, rb), (tc * rb[0] - ts * rb[1] + gx, ts * rb[0] + tc * rb[1] + gy),
                       math.hypot(rb[2], rb[3]) + 1e-6) for rb in T_RECTS]


def _corners_few(px, py, c, s, rect):
    cx, cy, hx, hy = rect
    local = ((cx - hx, cy - hy), (cx + hx, cy - hy), (cx + hx, cy + hy), (cx - hx, cy + hy))
    return [(c * lx - s * ly + px, s * lx + c * ly + py) for lx, ly in local]


def _overlap_few(pts, clipper):
    """`_overlap` of one quad pair: Sutherland-Hodgman by the clipper's four edges, then the shoelace area."""
    for k in range(4):
        (ax, ay), (bx, by) = clipper[k], clipper[(k + 1) % 4]
        ex, ey = bx - ax, by - ay
        n, out = len(pts), []
        for i in range(n):
            p0, p1 = pts[i]
            q0, q1 = pts[i + 1 if i + 1 < n else 0]
            sp = ex * (p1 - ay) - ey * (p0 - ax)
            sq = ex * (q1 - ay) - ey * (q0 - ax)
            if sp >= 0:
                out.append((p0, p1))
            if (sp >= 0) != (sq >= 0):
                denom = sp - sq
                t = sp / (denom if denom != 0 else 1.0)
                out.append((p0 + t * (q0 - p0), p1 + t * (q1 - p1)))
        pts = out
        if not pts:
            return 0.0
    n = len(pts)
    r = [0.0] * _SLOTS  # the array code's 8 slots, invalid ones 0, summed pairwise as NumPy sums 8 values
    for i in range(n):
        (p0, p1), (q0, q1) = pts[i], pts[i + 1 if i + 1 < n else 0]
        r[i] = p0 * q1 - q0 * p1
    return 0.5 * abs(((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7])))


def _coverage(pose, target=TARGET_POSE):
    xp = array_namespace(pose)
    tgt = xp.broadcast_to(xp.asarray(target, dtype=pose.dtype), pose.shape)
    pairs = [(ra, rb) for ra in T_RECTS for rb in T_RECTS]
    # the four (block rect, target rect) pairs clipped as one stacked batch: a quarter of the array calls
    subject = xp.stack([_rect_corners(pose, ra) for ra, _ in pairs])
    clipper = xp.stack([_rect_corners(tgt, rb) for _, rb in pairs])
    area = _overlap(subject, clipper)
    inter = ((area[0] + area[1]) + area[2]) + area[3]  # summed in the order the pairs were always summed
    return xp.clip(inter / T_AREA, 0.0, 1.0)


def coverage_np(pose, target=TARGET_POSE, block: int = 16384) -> np.ndarray:
    """`coverage` for large host batches: only poses within reach of the target can overlap it
    (exact shortcut), and the rest are done in blocks to bound the temporaries."""
    pose = np.atleast_2d(np.asarray(pose, np.float64))
    tgt = np.broadcast_to(np.asarray(target, np.float64), pose.shape)
    out = np.zeros(len(pose))
    near = np.flatnonzero(np.hypot(pose[:, 0] - tgt[:, 0], pose[:, 1] - tgt[:, 1]) < 2 * T_REACH)
    for lo in range(0, len(near), block):
        idx = near[lo : lo + block]
        out[idx] = _coverage(pose[idx], tgt[idx])
    return out


# -- episodes ------------------------------------------------------------------------------------
def episode_init(coverage0, success: float, terminate: bool, xp):
    """Per-world episode bookkeeping at reset. An episode that starts covered is over before its first step
    (when episodes terminate at all: a study run of a fixed schedule never does)."""
    hit = coverage0 >= success
    done = hit & terminate
    zeros = xp.zeros(coverage0.shape, dtype=coverage0.dtype)
    return {
        "done": done,
        "success": hit,
        "steps_to_success": xp.astype(xp.where(hit, 0, -1), xp.int32),
        "length": xp.zeros(coverage0.shape, dtype=xp.int32),
        "return": zeros,
        "coverage": coverage0,
        "best_coverage": coverage0,
    }


def episode_update(ep, reward, k, success: float, terminate: bool):
    """Fold control step k's reward (the coverage after it) into the episode; finished episodes stay frozen."""
    xp = array_namespace(reward)
    if all_live(ep["done"]) and reward.dtype == ep["coverage"].dtype:
        return _episode_update_live(ep, reward, k, success, terminate)
    return _episode_update_select(ep, reward, k, success, terminate)


def _episode_update_select(ep, reward, k, success: float, terminate: bool):
    xp = array_namespace(reward)
    live = ~ep["done"]
    hit = live & (reward >= success)
    k1 = xp.astype(xp.asarray(k + 1), xp.int32)
    return {
        "done": (ep["done"] | hit) if terminate else ep["done"],
        "success": ep["success"] | hit,
        "steps_to_success": xp.where(hit & (ep["steps_to_success"] < 0), k1, ep["steps_to_success"]),
        "length": xp.where(live, k1, ep["length"]),
        "return": xp.where(live, ep["return"] + reward, ep["return"]),
        "coverage": xp.where(live, reward, ep["coverage"]),
        "best_coverage": xp.where(live, xp.maximum(ep["best_coverage"], reward), ep["best_coverage"]),
    }


def all_live(done) -> bool:
    """On the host, no episode of the batch has ended: every per-row select of `live` picks its first
    argument, so it can be left out (the same values; the usual case of an env's step)."""
    return isinstance(done, np.ndarray) and not done.any()


def _episode_update_live(ep, reward, k, success: float, terminate: bool):
    """`episode_update` where every episode is live (host arrays): each `where(live, a, b)` is `a`."""
    hit = reward >= success
    k1 = np.asarray(k + 1).astype(np.int32)
    return {
        "done": (ep["done"] | hit) if terminate else ep["done"],
        "success": ep["success"] | hit,
        "steps_to_success": np.where(hit & (ep["steps_to_success"] < 0), k1, ep["steps_to_success"]),
        "length": np.zeros_like(ep["length"]) + k1,
        "return": ep["return"] + reward,
        "coverage": reward.copy(),
        "best_coverage": np.maximum(ep["best_coverage"], reward),
    }
