"""Outcomes of a rollout compared across backends: pose vectors, outcome modes, where paths part, distribution distances."""

from __future__ import annotations

import numpy as np

from mjx_pusht.backends.results import Rollouts

DIVERGED_M = 1e-4  # a seed's paths have parted once the tee positions differ by this much


YAW_LENGTH = 0.06  # metres per radian when a pose is one vector: the bar's half-length


SPIN_RAD = 0.6  # |final yaw| beyond this is a spun T; the outcome modes sit near 0 and +-1.2 rad


def pose_vectors(r: Rollouts) -> np.ndarray:
    """Final poses as (x, y, L*yaw) in metres, so position and turn weigh alike."""
    return np.column_stack([r.final[:, 0], r.final[:, 1], YAW_LENGTH * r.final[:, 2]])


def energy_distance(a: np.ndarray, b: np.ndarray, block: int = 2048) -> float:
    """Multivariate two-sample energy distance 2E|X-Y| - E|X-X'| - E|Y-Y'| (0 iff same distribution)."""

    def mean_dist(x, y):
        total = 0.0
        for i in range(0, len(x), block):
            d = x[i : i + block, None, :] - y[None, :, :]
            total += np.sqrt((d * d).sum(-1)).sum()
        return total / (len(x) * len(y))

    return float(2 * mean_dist(a, b) - mean_dist(a, a) - mean_dist(b, b))


MODES = ("straight", "spun_ccw", "spun_cw")


def modes(yaw) -> np.ndarray:
    """Each final yaw's outcome mode: pushed straight, spun counter-clockwise (positive) or clockwise."""
    yaw = np.asarray(yaw)
    return np.where(yaw >= SPIN_RAD, "spun_ccw", np.where(yaw <= -SPIN_RAD, "spun_cw", "straight"))


def outcome_modes(r: Rollouts) -> dict[str, float]:
    """Share of seeds ending in each mode (the yaw as the hinge counted it)."""
    m, n = modes(r.final[:, 2]), max(len(r.final), 1)
    return {k: float((m == k).sum() / n) for k in MODES}


def divergence_steps(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per seed, the first frame where tee positions differ by more than DIVERGED_M (frames if never)."""
    err = np.linalg.norm(a[..., :2] - b[..., :2], axis=-1)
    over = err > DIVERGED_M
    return np.where(over.any(axis=1), over.argmax(axis=1), a.shape[1])


def tee_traj(model, r: Rollouts) -> np.ndarray:
    from mjx_pusht.model.layout import QposLayout

    return QposLayout.of(model).tee_pose(r.trace.qpos)


def final_diff(a: Rollouts, b: Rollouts) -> dict:
    d = np.linalg.norm(a.final[:, :2] - b.final[:, :2], axis=1)
    return {"median_m": float(np.median(d)), "frac_over_1mm": float((d > 1e-3).mean()), "max_m": float(d.max())}
