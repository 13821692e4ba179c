"""Statistics every report shares: sample distributions, Wilson intervals, paired differences, episode summaries.

The episodes run through the same backends, chunks, resume and out-of-memory halving as a
sweep (sweep.run_sweep); this module adds the episode table and the summary a policy
evaluation reports: the success rate with its 95% Wilson interval, steps to success, coverage
and return.
"""

from __future__ import annotations

import math

import numpy as np

from mjx_pusht.backends.results import Rollouts


def wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson score interval for a binomial proportion (95% by default): honest at 0 and 1."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # at p = 0 or 1 the interval touches its bound exactly (rounding would leave 0.9999999999999999)
    return (0.0 if successes == 0 else max(0.0, centre - half), 1.0 if successes == n else min(1.0, centre + half))


def distribution(x) -> dict:
    """The one summary of a sample every report uses: count, extremes, mean and quantiles (just n when empty)."""
    x = np.asarray(x, float)
    if x.size == 0:
        return {"n": 0}
    q = np.quantile(x, [0.05, 0.25, 0.5, 0.75, 0.95, 0.99])
    return {"n": int(x.size), "min": float(x.min()), "p05": float(q[0]), "p25": float(q[1]), "median": float(q[2]),
            "mean": float(x.mean()), "p75": float(q[3]), "p95": float(q[4]), "p99": float(q[5]), "max": float(x.max())}


def warning_summary(r: Rollouts) -> dict:
    """The rows MuJoCo warned about (a singular model, a world it reset): how many, which, and what it said."""
    from mjx_pusht.model.params import warning_names

    warned = r.warned
    bits = int(np.bitwise_or.reduce(r.warnings[warned])) if warned.any() else 0
    return {"n_mujoco_warnings": int(warned.sum()), "mujoco_warning_seeds": [int(s) for s in r.seeds[warned][:100]],
            "mujoco_warnings": warning_names(bits)}


def steps_text(median_steps: float | None) -> str:
    """A summary's median steps to success as a reader reads it: a number of steps, or why there is none (the
    summary keeps None, JSON's null; a printed "None" read as a bug)."""
    return "- (no episode succeeded)" if median_steps is None else f"{median_steps:g}"


def summarize_episodes(r: Rollouts) -> dict:
    """The episode outcomes: success rate and interval over finite episodes, steps to success, coverage, return."""
    ep = r.episode
    finite = r.finite
    ok = np.asarray(ep["success"], bool) & finite
    n = int(finite.sum())
    k = int(ok.sum())
    lo, hi = wilson(k, n)
    steps = np.asarray(ep["steps_to_success"])[ok]
    return {
        "n_episodes": int(len(r)),
        "n_finite": n,
        "n_success": k,
        "success_rate": k / n if n else 0.0,
        "success_rate_ci95": [lo, hi],
        "steps_to_success": distribution(steps),
        "median_steps_to_success": float(np.median(steps)) if steps.size else None,  # None: no success to count
        "final_coverage": distribution(np.asarray(ep["coverage"])[finite]),
        "best_coverage": distribution(np.asarray(ep["best_coverage"])[finite]),
        "return": distribution(np.asarray(ep["return"])[finite]),
        "episode_length": distribution(np.asarray(ep["length"])[finite]),
        "n_rigid": int(r.rigid.sum()),
        "n_non_finite": int((~finite).sum()),
        "non_finite_seeds": [int(s) for s in r.seeds[~finite][:100]],
        "n_escaped": int((~r.contained).sum()),
        "escaped_seeds": [int(s) for s in r.seeds[~r.contained][:100]],
        **warning_summary(r),
    }
