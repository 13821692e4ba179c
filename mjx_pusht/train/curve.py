"""A training run's curve: held-out success after every fit, written as curve.csv, curve.png and train.rrd
(`write_curve`); and which fit --keep names (`kept`, by the validation rollout `validated` admits)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_pusht.io.outputs import atomic_write_bytes

CURVE_COLUMNS = ("iteration", "beta", "env_steps", "samples", "loss", "success", "success_lo", "success_hi",
                 "coverage", "sim_seconds", "learn_seconds", "wall_seconds", "pose_error_mm", "validation_success",
                 "validation_beta")


# --keep best: a fit's validation rollout (DAgger's next rollout, the expert acting in `beta` of its control steps and
# setting the student's memory when it does) counts once the expert acts this little in it. Over every committed
# DAgger run's curve, that rollout's success minus the student's own held-out success was +3.85 points on average
# (at most +13.1) for beta in (0.003, 0.01], +0.93 in (0.001, 0.003], +0.28 in (0.0003, 0.001], -0.04 at or below
# 0.0003. With 0.01 here, two of three pixel runs on one H200 kept iteration 12 (held-out 92.3%, 93.4%), whose
# validation had the expert's help, over late fits at 96-97% (notebook door.md).
VALIDATION_BETA = 3e-4


def validated(row: dict) -> bool:
    """Whether a curve row's validation rollout counts: there was one, and the expert acted in at most
    VALIDATION_BETA of it (rows written before validation was recorded have neither key)."""
    beta = row.get("validation_beta")
    return row.get("validation_success") is not None and beta is not None and beta <= VALIDATION_BETA


def kept(curve: list[dict], keep: str) -> dict | None:
    """The curve row of the fit --keep names: the last, or the best by validation success among the fits
    `validated` (the last when none is)."""
    if not curve:
        return None
    rows = [r for r in curve if validated(r)]
    if keep == "last" or not rows:
        return curve[-1]
    return max(reversed(rows), key=lambda r: r["validation_success"])  # a tie: the later fit


def reached(curve: list[dict], until: float | None) -> str | None:
    """--until: why training ends at the curve's last judgement (its held-out success at least `until`), or None.
    Both trainers stop so, DAgger before learning the samples of the rollout that judged, PPO between Brax's epochs."""
    if until is None or not curve or curve[-1]["success"] < until:
        return None
    return f"its held-out success {curve[-1]['success']:.1%} reached --until {until:g}"


def write_curve(out: Path, curve: list[dict], title: str, rerun: bool = True) -> None:
    """curve.csv, curve.png (held-out success with its 95% band, by env steps and by wall-clock), train.rrd."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # a method's own columns after the shared ones (PPO: both actions' success, Brax's loss metrics)
    columns = list(CURVE_COLUMNS) + sorted({k for r in curve for k in r} - set(CURVE_COLUMNS))
    lines = [",".join(columns)] + [",".join(f"{r[c]:.6g}" if isinstance(r.get(c), float) else
                                            "" if r.get(c) is None else str(r[c])
                                            for c in columns) for r in curve]
    atomic_write_bytes(out / "curve.csv", ("\n".join(lines) + "\n").encode())
    kl = [(r["wall_seconds"] / 60, r["brax_kl"]) for r in curve if r.get("brax_kl") is not None]
    fig, axes = plt.subplots(1, 3 if kl else 2, figsize=(15 if kl else 10, 3.8))
    for ax, key, label in ((axes[0], "env_steps", "env control steps (millions)"),
                           (axes[1], "wall_seconds", "training wall-clock (minutes)")):
        scale = 1e6 if key == "env_steps" else 60.0
        xs = np.array([r[key] for r in curve]) / scale
        ax.fill_between(xs, [100 * r["success_lo"] for r in curve], [100 * r["success_hi"] for r in curve], alpha=0.3)
        ax.plot(xs, [100 * r["success"] for r in curve], "o-", label="held-out success")
        val = [(x, 100 * r["validation_success"]) for x, r in zip(xs, curve) if validated(r)]
        if val:  # what --keep best chooses by: seeds never held out (DAgger: the next rollout's, expert share <= 1%)
            ax.plot(*zip(*val), ".--", alpha=0.6, label="validation (seeds never held out)")
        ax.set_xlabel(label)
        ax.set_ylim(0, 100)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success, % (coverage >= 0.95 in 300 steps)")
    if kl:  # PPO: the policy's change in the epoch before each judgement (a spike came before every collapse)
        axes[2].semilogy(*zip(*kl), "o-", color="tab:red")
        axes[2].set_xlabel("training wall-clock (minutes)")
        axes[2].set_ylabel("Brax's KL, old to new policy, that epoch")
        axes[2].grid(alpha=0.3, which="both")
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(out / "curve.png", buf.getvalue())
    if rerun:
        _record_curve(out / "train.rrd", curve)


def _record_curve(path: Path, curve: list[dict]) -> None:
    import rerun as rr

    rec = rr.RecordingStream("mjx_pusht_train")
    tmp = path.with_name(f".{path.name}.tmp")  # written whole, then renamed: never a half recording
    rec.save(str(tmp))
    for r in curve:
        rec.set_time("env_steps", sequence=int(r["env_steps"]))
        rec.log("curve/held_out_success", rr.Scalars(r["success"]))
        rec.log("curve/held_out_coverage", rr.Scalars(r["coverage"]))
        if r["loss"] is not None:  # PPO's curve has no fit loss of ours
            rec.log("curve/loss", rr.Scalars(r["loss"]))
    rec.flush()
    rec.disconnect()
    tmp.replace(path)
