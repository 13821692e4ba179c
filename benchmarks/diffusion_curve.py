"""Success against training minutes, from lerobot-train's own logs (its `--env_eval_freq` evals on the batch).

    python -m benchmarks.diffusion_curve --json curve.json --png curve.png 200=hold1.log,hold2.log 2000=hold1.log

Each run is NAME=LOG[,LOG...]: the logs of one `lerobot-train` output folder in the order they were written, one
a machine hold (a hold that resumed from a checkpoint starts a new log). lerobot 0.6.1 logs a line per
`--log_freq` steps ("step:N ... updt_s:... data_s:..."), "Eval policy at step N" before an eval and "Suite
overall aggregated: {...}" after it (pc_success, n_episodes, eval_s), each stamped to the second. A point's
training minutes are the wall-clock from each log's "Start offline training" to the eval, summed over the
run's logs, less the seconds its evals took (eval_s): checkpoint saving stays in, and steps redone after a
resume count again (minutes spent, not minutes needed). Its interval is Wilson's 95% over the eval's episodes.
"""

from __future__ import annotations

import argparse
import ast
import json
import re
import sys
from datetime import datetime
from pathlib import Path

STAMP = r"INFO (\d{4}-\d\d-\d\d \d\d:\d\d:\d\d) "
START = re.compile(STAMP + r".*Start offline training")
# LeRobot writes counts past 999 as format_big_number does ("step:5K", "step:1.2M"): the step of a log line is
# that rounding; an eval's step ("Eval policy at step 5200") is exact
STEP = re.compile(STAMP + r".*? step:(\d+(?:\.\d+)?[KMBT]?) .*?loss:([0-9.eE+-]+)")
EVAL_AT = re.compile(STAMP + r".*Eval policy at step (\d+)")
OVERALL = re.compile(STAMP + r".*Suite overall aggregated: (\{.*\})\s*$")


def _count(text: str) -> int:
    """'900' -> 900, '5K' -> 5000, '1.2M' -> 1200000: the inverse of LeRobot's format_big_number, to its rounding."""
    scale = {"K": 10**3, "M": 10**6, "B": 10**9, "T": 10**12}.get(text[-1], 1)
    return round(float(text.rstrip("KMBT")) * scale)


def _t(stamp: str) -> datetime:
    return datetime.strptime(stamp, "%Y-%m-%d %H:%M:%S")


def parse_run(logs: list[Path]) -> dict:
    """The eval points and the last training step of one run's logs (in hold order)."""
    from mjx_pusht.study.stats import wilson

    points, losses, spent_s, eval_total_s, last_step = [], [], 0.0, 0.0, 0
    for log in logs:
        start = step_at_eval = None
        end_s = 0.0
        for line in log.read_text(errors="replace").splitlines():
            if m := START.search(line):
                start = _t(m[1])
            elif start is None:
                continue
            elif m := STEP.search(line):
                step = _count(m[2])
                last_step = max(last_step, step)
                losses.append({"step": step, "loss": float(m[3])})
                end_s = (_t(m[1]) - start).total_seconds()
            elif m := EVAL_AT.search(line):
                step_at_eval = int(m[2])
                last_step = max(last_step, step_at_eval)
            elif (m := OVERALL.search(line)) and step_at_eval is not None:
                o = ast.literal_eval(m[2])  # LeRobot logs the dict's repr
                end_s = (_t(m[1]) - start).total_seconds()
                eval_total_s += o["eval_s"]
                n = int(o["n_episodes"])
                k = round(o["pc_success"] * n / 100)
                lo, hi = wilson(k, n)
                points.append({"step": step_at_eval, "train_min": (spent_s + end_s - eval_total_s) / 60,
                               "wall_min": (spent_s + end_s) / 60, "pc_success": o["pc_success"], "successes": k,
                               "n_episodes": n, "wilson95": [100 * lo, 100 * hi], "avg_sum_reward": o["avg_sum_reward"],
                               "eval_s": o["eval_s"]})
                step_at_eval = None
        if start is None:
            raise SystemExit(f"{log}: no 'Start offline training' line: not a lerobot-train log")
        spent_s += end_s
    return {"logs": [str(p) for p in logs], "points": points, "last_step": last_step,
            "train_min": (spent_s - eval_total_s) / 60, "wall_min": spent_s / 60, "losses": losses}


def plot(runs: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for name, run in runs.items():
        p = run["points"]
        x = [q["train_min"] for q in p]
        label = f"{name} episodes" if name.isdigit() else name  # a size, or a run's own name
        ax.plot(x, [q["pc_success"] for q in p], marker="o", label=label)
        ax.fill_between(x, [q["wilson95"][0] for q in p], [q["wilson95"][1] for q in p], alpha=0.2)
    ax.axhline(80, color="grey", lw=0.8, ls="--")
    ax.set(xlabel="training minutes (evals left out)", ylabel="success % on --env.type=mjx_pusht", ylim=(0, 100),
           title="LeRobot Diffusion Policy on mjx-pusht demos")
    ax.legend(title="demos")
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="+", help="NAME=LOG[,LOG...] per run, its logs in hold order")
    p.add_argument("--json", type=Path, required=True)
    p.add_argument("--png", type=Path, default=None)
    p.add_argument("--after", action="append", default=[], metavar="NAME=MINUTES,STEPS",
                   help="run NAME started from another run's checkpoint (diffusion_pusht.sh FROM=) taken after MINUTES "
                        "of training and STEPS updates: its points are placed after them, so the curve reads as the "
                        "policy's whole training")
    a = p.parse_args(argv)
    runs = {}
    for spec in a.runs:
        name, sep, logs = spec.partition("=")
        if not sep or not logs:
            p.error(f"{spec!r}: give NAME=LOG[,LOG...]")
        paths = [Path(x) for x in logs.split(",")]
        if missing := [str(x) for x in paths if not x.is_file()]:
            p.error(f"{spec!r}: no log file {', '.join(missing)}")
        runs[name] = parse_run(paths)
    for spec in a.after:
        name, _, offset = spec.partition("=")
        try:
            minutes, steps = offset.split(",")
            minutes, steps = float(minutes), int(steps)
        except ValueError:  # not two values, or not numbers
            p.error(f"--after {spec!r}: give NAME=MINUTES,STEPS (e.g. 2000=12.9,8000)")
        if name not in runs:
            p.error(f"--after {spec!r}: no run named {name!r}")
        run = runs[name]
        run["after"] = {"train_min": minutes, "steps": steps}
        for q in run["points"]:
            q["step"] += steps
            q["train_min"] += minutes
            q["wall_min"] += minutes
        run["last_step"] += steps
        run["train_min"] += minutes
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps(runs, indent=1) + "\n")
    if a.png:
        plot(runs, a.png)
    for name, run in runs.items():
        last = run["points"][-1] if run["points"] else {}
        print(f"{name}: {len(run['points'])} evals, step {run['last_step']}, {run['train_min']:.1f} training min; "
              f"last eval {last.get('pc_success', float('nan')):.1f}% at {last.get('train_min', float('nan')):.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
