"""The PushT task score of a final pose: position error, wrapped yaw error, coverage, success.

Coverage (area of block T intersect target T over the T's area) is defined once, in
`task.py`, for NumPy and JAX arrays alike; this module scores host-side tables with it.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht.task.rules import (
    SUCCESS_COVERAGE,
    T_AREA,
    T_REACH,
    T_RECTS,
    TARGET_POSE,
    wrap_angle,
)
from mjx_pusht.task.rules import coverage_np as coverage

__all__ = ["SUCCESS_COVERAGE", "T_AREA", "T_REACH", "T_RECTS", "TARGET_POSE", "coverage", "task_score", "wrap_angle"]


def task_score(final: np.ndarray, target=TARGET_POSE) -> dict[str, np.ndarray]:
    """Per seed: position error (m), yaw error wrapped to (-pi, pi], coverage, and success (coverage >= 0.95), against
    the target pose, or (N, 3) targets (random goals: each row's own)."""
    final = np.atleast_2d(np.asarray(final, np.float64))
    tgt = np.broadcast_to(np.asarray(target, float), final.shape)
    cov = coverage(final, tgt)
    return {
        "pos_err": np.hypot(final[:, 0] - tgt[:, 0], final[:, 1] - tgt[:, 1]),
        "yaw_err": wrap_angle(final[:, 2] - tgt[:, 2]),
        "coverage": cov,
        "success": cov >= SUCCESS_COVERAGE,
    }
