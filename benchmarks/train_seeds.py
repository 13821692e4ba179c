"""One training recipe on several seeds, reported as one result: every seed's run, then the aggregate.

    python -m benchmarks.train_seeds --seeds 0,1,2 --out runs/ppo -- --algo ppo --backend mjx-warp ...
    python -m benchmarks.train_seeds --collect runs/ppo/seed-0 runs/ppo/seed-1 --out runs/ppo

The first form runs `mjx-pusht train ARGS --seed S --out OUT/seed-S` for each seed in turn (a seed whose
folder already holds a finished run is read, not run again, so a killed sweep goes on where it stopped);
the second reads finished runs. Either writes OUT/seeds.json and OUT/seeds.md: each seed's held-out
success as `eval` judged it (with its 95% interval), the trainer's own judgement beside it, the kept
iteration, iterations and training wall-clock, and the lowest held-out judgement later than the first at or
above 80% (`low_after`: a curve that rises and stays keeps it high, one that collapses and recovers does not);
then the mean, sample sd, min and max of the held-out rates over the seeds, and the share of seeds at or above
--goal; and OUT/seeds.png, every seed's held-out curve. Nothing is dropped: a run that failed is listed as
failed, and the aggregate says over how many seeds it is.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

from mjx_pusht.io.outputs import atomic_write_bytes, atomic_write_json


RISEN = 0.8  # low_after: the lowest judgement after the first at or above this


def low_after(curve: list[dict], risen: float = RISEN) -> float | None:
    """The lowest held-out judgement later than the first at or above `risen` (None if there is none)."""
    first = next((i for i, r in enumerate(curve) if r["success"] >= risen), None)
    later = [] if first is None else [r["success"] for r in curve[first + 1:]]
    return min(later) if later else None


def row(run: Path) -> dict:
    """One finished run's line: eval's held-out rate (what to report) and the trainer's own judgement."""
    if not (run / "summary.json").is_file():  # e.g. a run cut off with the machine: only its first fits or checkpoints
        raise ValueError("no summary.json: the run did not finish")
    s = json.loads((run / "summary.json").read_text())
    ev = s.get("eval")
    if ev is None:
        raise ValueError("summary.json has no eval: the run did not finish")
    trainer = s.get("trainer_success", s.get("final_success"))  # older summaries named it final_success
    return {"run": str(run), "seed": s["config"]["seed"], "method": s["method"], "obs_type": s["obs_type"],
            "device": s["device"], "held_out_success": ev["success_rate"], "held_out_ci95": ev["success_rate_ci95"],
            "n_episodes": ev["n_episodes"], "trainer_success": trainer,
            "kept": (s.get("kept") or {}).get("iteration", s["curve"][-1]["iteration"] if s.get("curve") else None),
            "keep": (s.get("kept") or {}).get("rule", "last"), "iterations_run": s["iterations_run"],
            "env_steps": s["env_steps"], "wall_seconds": s["wall_seconds"], "low_after": low_after(s.get("curve") or [])}


def aggregate(rows: list[dict], goal: float | None) -> dict:
    rates = [r["held_out_success"] for r in rows]
    out = {"n_seeds": len(rates), "seeds": [r["seed"] for r in rows], "mean": statistics.fmean(rates),
           "sd": statistics.stdev(rates) if len(rates) > 1 else None, "min": min(rates), "max": max(rates),
           "wall_seconds_mean": statistics.fmean(r["wall_seconds"] for r in rows)}
    if goal is not None:
        out |= {"goal": goal, "seeds_at_goal": sum(r >= goal for r in rates)}
    return out


def markdown(rows: list[dict], agg: dict, failed: list[str]) -> str:
    lines = ["| seed | held-out (eval) | 95% interval | trainer's judgement | kept iteration | iterations | "
             f"training wall-clock | lowest judgement after first {RISEN:.0%} |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lo, hi = r["held_out_ci95"]
        lines.append(f"| {r['seed']} | {r['held_out_success']:.1%} | {lo:.1%}-{hi:.1%} | {r['trainer_success']:.1%} | "
                     f"{r['kept']} ({r['keep']}) | {r['iterations_run']} | {r['wall_seconds'] / 60:.1f} min | "
                     f"{'n/a' if r['low_after'] is None else format(r['low_after'], '.1%')} |")
    sd = "n/a" if agg["sd"] is None else f"{agg['sd']:.1%}"
    lines += ["", f"{agg['n_seeds']} seeds on {rows[0]['device']}: mean {agg['mean']:.1%}, sd {sd}, "
              f"min {agg['min']:.1%}, max {agg['max']:.1%}" +
              (f"; {agg['seeds_at_goal']} of {agg['n_seeds']} at or above {agg['goal']:.0%}" if "goal" in agg else "")]
    lines += [f"failed (not in the aggregate): {f}" for f in failed]
    return "\n".join(lines) + "\n"


def plot(runs: list[Path], path: Path) -> None:
    """seeds.png: every seed's held-out curve by training wall-clock on one axis (a collapse shows as a fall)."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.8))
    for run in runs:
        s = json.loads((run / "summary.json").read_text())
        curve = s["curve"]
        ax.plot([r["wall_seconds"] / 60 for r in curve], [100 * r["success"] for r in curve], "o-", ms=3,
                label=f"seed {s['config']['seed']}")
    ax.axhline(100 * RISEN, color="grey", lw=0.8, ls=":")
    ax.set_xlabel("training wall-clock (minutes)")
    ax.set_ylabel("held-out success, %")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", default=None, help="comma-separated seeds to train (with train's arguments after --)")
    p.add_argument("--collect", nargs="+", type=Path, default=None, help="finished run folders to aggregate instead")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--goal", type=float, default=None, help="a held-out rate (e.g. 0.95) to count seeds against")
    args, train_args = p.parse_known_args(argv)
    train_args = [a for a in train_args if a != "--"]
    if (args.seeds is None) == (args.collect is None):
        p.error("give --seeds (and train's arguments after --) or --collect RUN ...")
    if any(a in ("--seed", "--out") for a in train_args):
        p.error("--seed and --out are this script's to set for each run")
    args.out.mkdir(parents=True, exist_ok=True)
    runs, failed = list(args.collect or []), []
    if args.seeds is not None:
        try:
            seeds = [int(s) for s in args.seeds.split(",")]
        except ValueError:
            p.error(f"--seeds takes comma-separated integers, got {args.seeds!r}")
        for seed in seeds:
            run = args.out / f"seed-{seed}"
            runs.append(run)
            if (run / "summary.json").is_file() and "eval" in json.loads((run / "summary.json").read_text()):
                print(f"seed {seed}: finished before, read from {run}")
                continue
            cmd = [sys.executable, "-m", "mjx_pusht", "train", *train_args, "--seed", str(seed), "--out", str(run)]
            print("$", " ".join(cmd), flush=True)
            t = time.perf_counter()
            rc = subprocess.call(cmd)
            print(f"seed {seed}: exit {rc} after {time.perf_counter() - t:.0f} s", flush=True)
    rows = []
    for run in runs:
        try:
            rows.append(row(run))
        except (OSError, KeyError, ValueError) as e:  # unreadable, cut or unfinished: listed, not dropped
            failed.append(f"{run} ({e})")
    if not rows:
        atomic_write_json(args.out / "seeds.json", {"runs": [], "aggregate": None, "failed": failed})
        print("no finished run to aggregate:\n" + "\n".join(failed), file=sys.stderr)
        return 1
    agg = aggregate(rows, args.goal)
    atomic_write_json(args.out / "seeds.json", {"runs": rows, "aggregate": agg, "failed": failed})
    text = markdown(rows, agg, failed)
    atomic_write_bytes(args.out / "seeds.md", text.encode())
    plot([Path(r["run"]) for r in rows], args.out / "seeds.png")
    print(text, end="")
    return 0 if not failed else 1


if __name__ == "__main__":
    raise SystemExit(main())
