"""The PushT task score: how far the tee is from the target pose, and how much of the target T it covers.

Coverage is the area of (block T intersect target T) over the T's area, the quantity
PushT environments score (success at 0.95 or more). A T is two disjoint rectangles
(bar and stem), so the overlap of two Ts is the sum of the four convex rectangle
intersections, each clipped exactly (Sutherland-Hodgman), vectorised over seeds.
"""

from __future__ import annotations

import numpy as np

# The T in its own frame (the tee body / target body origin): bar and stem rectangles as
# (centre_x, centre_y, half_x, half_y), from the scene's geoms.
T_RECTS = ((0.0, 0.0, 0.06, 0.015), (0.0, -0.06, 0.015, 0.045))
T_AREA = sum(4 * hx * hy for _, _, hx, hy in T_RECTS)
TARGET_POSE = (0.0, 0.0, 0.0)
SUCCESS_COVERAGE = 0.95


def wrap_angle(a):
    """Wrap to (-pi, pi]."""
    w = np.mod(np.asarray(a, float) + np.pi, 2 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def _corners(pose: np.ndarray, rect) -> np.ndarray:
    """(N, 4, 2) corners, counter-clockwise, of one T rectangle placed at (x, y, yaw) poses."""
    cx, cy, hx, hy = rect
    local = np.array([[cx - hx, cy - hy], [cx + hx, cy - hy], [cx + hx, cy + hy], [cx - hx, cy + hy]])
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # (N, 2, 2)
    return np.einsum("nij,kj->nki", rot, local) + pose[:, None, :2]


def _clip(poly: np.ndarray, valid: np.ndarray, a: np.ndarray, b: np.ndarray):
    """Clip (N, M, 2) polygons (first `valid` vertices used) by the half-plane left of edge a->b."""
    n, m, _ = poly.shape
    out = np.zeros((n, 2 * m, 2))
    count = np.zeros(n, int)
    edge = b - a

    def side(p):
        return edge[:, 0] * (p[..., 1] - a[:, 1]) - edge[:, 1] * (p[..., 0] - a[:, 0])

    for i in range(m):
        j = (i + 1) % m
        use = i < valid
        nxt = np.where(j < valid, j, 0)
        p, q = poly[np.arange(n), i], poly[np.arange(n), nxt]
        sp, sq = side(p), side(q)
        t = sp / np.where(sp - sq == 0, 1, sp - sq)
        cross = p + t[:, None] * (q - p)
        for keep, pt in (((sp >= 0) & use, None), (((sp >= 0) != (sq >= 0)) & use, cross)):
            if pt is None:
                pt = p
            idx = np.flatnonzero(keep)
            out[idx, count[idx]] = pt[idx]
            count[idx] += 1
    return out, count


def _area(poly: np.ndarray, count: np.ndarray) -> np.ndarray:
    m = poly.shape[1]
    nxt = (np.arange(m)[None, :] + 1) % np.maximum(count, 1)[:, None]
    idx = np.arange(m)[None, :] < count[:, None]
    q = np.take_along_axis(poly, nxt[..., None].repeat(2, -1), axis=1)
    cross = poly[..., 0] * q[..., 1] - q[..., 0] * poly[..., 1]
    return 0.5 * np.abs(np.where(idx, cross, 0.0).sum(-1))


def _rect_overlap(pa: np.ndarray, ra, pb: np.ndarray, rb) -> np.ndarray:
    subject = _corners(pa, ra)
    clipper = _corners(pb, rb)
    poly, count = subject, np.full(len(pa), 4)
    for k in range(4):
        poly, count = _clip(poly, count, clipper[:, k], clipper[:, (k + 1) % 4])
    return _area(poly, count)


# Every point of a T lies within this distance of its body origin (the stem's far corners),
# so two Ts whose origins are more than twice this apart cannot overlap at all.
T_REACH = max(np.hypot(abs(cx) + hx, abs(cy) + hy) for cx, cy, hx, hy in T_RECTS)


def coverage(pose: np.ndarray, target=TARGET_POSE) -> np.ndarray:
    """Fraction of the target T's area covered by the block T at each (x, y, yaw) pose, in [0, 1]."""
    pose = np.atleast_2d(np.asarray(pose, float))
    tgt = np.broadcast_to(np.asarray(target, float), pose.shape)
    out = np.zeros(len(pose))
    # exact shortcut: only poses within reach of the target can overlap it
    near = np.flatnonzero(np.hypot(pose[:, 0] - tgt[:, 0], pose[:, 1] - tgt[:, 1]) < 2 * T_REACH)
    if near.size:
        p, t = pose[near], tgt[near]
        inter = sum(_rect_overlap(p, ra, t, rb) for ra in T_RECTS for rb in T_RECTS)
        out[near] = np.clip(inter / T_AREA, 0.0, 1.0)
    return out


def task_score(final: np.ndarray, target=TARGET_POSE) -> dict[str, np.ndarray]:
    """Per seed: position error (m), yaw error wrapped to (-pi, pi], coverage, and success (coverage >= 0.95)."""
    final = np.atleast_2d(final)
    tgt = np.asarray(target, float)
    cov = coverage(final, tgt)
    return {
        "pos_err": np.hypot(final[:, 0] - tgt[0], final[:, 1] - tgt[1]),
        "yaw_err": wrap_angle(final[:, 2] - tgt[2]),
        "coverage": cov,
        "success": cov >= SUCCESS_COVERAGE,
    }
