"""One training run on 1, 2 and 4 devices of one host (`train --devices N`), the same run otherwise: how much faster
training goes, and how much sooner it reaches its goal rate.

    python -m benchmarks.train_scaling --devices 1,2,4 --goal 0.95 --out runs/scaling -- --backend mjx-warp ...

Runs `mjx-pusht train ARGS --devices N --out OUT/devices-N` for each count in turn (a count whose folder already
holds a finished run is read, not run again; `--collect` reads and runs nothing), then writes OUT/scaling.json and
OUT/scaling.md: for each count the control steps a second during training (the env steps learned from over the
training wall-clock; DAgger's also over its rollouts' seconds alone), each as a multiple of one device's, the
minutes of training wall-clock to the first held-out judgement at or above --goal (None if never), and eval's
held-out success of the kept policy.

`--per-device envs,batch` makes the named train flags one device's share, multiplied by the count (weak scaling:
every device does one device's work, the run's batches grow with the devices, as Brax's and Isaac Lab's scaling
figures count); without it the one run's work is split over the devices (strong scaling). The mode is recorded.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.train_seeds import row
from mjx_pusht.io.outputs import atomic_write_bytes, atomic_write_json


def measure(run: Path, goal: float) -> dict:
    """One finished run's throughput and time to the goal rate, from its summary.json and curve."""
    s = json.loads((run / "summary.json").read_text())
    r = row(run)
    curve = s["curve"]
    # PPO's learning_seconds are Brax's epochs (its rollouts and updates in one program); DAgger's wall-clock holds
    # its rollouts, fits and judgements, its simulation_seconds the rollouts alone
    train_s = s["learning_seconds"] if s["method"] == "ppo" else s["wall_seconds"]
    at_goal = next((c for c in curve if c["success"] >= goal), None)
    # after the first epoch or iteration (XLA's compiles, Warp's captures, DAgger's first fits): a run stopped at its
    # goal in under a minute spends a third of it there, which the whole run's rate counts against the devices.
    # PPO: Brax's epochs after its first (rows from 2: row 0 judges the untrained network), judgements left out;
    # DAgger: the wall-clock from its first judgement to its last, rollouts, fits and judgements together.
    first = 1 if s["method"] == "ppo" else 0  # the row the steady rate counts from
    later = curve[first + 1:]
    steady_s = (sum(c["learn_seconds"] for c in later) if s["method"] == "ppo"
                else curve[-1]["wall_seconds"] - curve[first]["wall_seconds"] if later else 0.0)
    return {"devices": s.get("devices", 1), "device": s["device"], "method": s["method"], "obs_type": s["obs_type"],
            "envs": s.get("config", {}).get("envs"), "env_steps": s["env_steps"], "training_seconds": train_s,
            "steps_per_second": s["env_steps"] / train_s if train_s else None,
            "steady_steps_per_second": ((curve[-1]["env_steps"] - curve[first]["env_steps"]) / steady_s
                                        if steady_s > 0 else None),
            "rollout_steps_per_second": (s["env_steps"] / s["simulation_seconds"]
                                         if s["method"] == "dagger" and s["simulation_seconds"] else None),
            "minutes_to_goal": None if at_goal is None else at_goal["wall_seconds"] / 60,
            "held_out_success": r["held_out_success"], "held_out_ci95": r["held_out_ci95"]}


def per_device(train_args: list[str], flags: list[str], n: int) -> list[str]:
    """`train_args` with each of `flags` (names without dashes) multiplied by `n`; a flag that is not there, or
    not an integer, is a one-line error (exit 1), not a run of the wrong size."""
    out = list(train_args)
    for flag in flags:
        opt = f"--{flag}"
        where = [i for i, a in enumerate(out) if a == opt]
        if not where or where[-1] + 1 >= len(out):
            raise SystemExit(f"train_scaling: --per-device {flag}: no {opt} VALUE in the train arguments")
        i = where[-1] + 1  # argparse keeps a flag's last value
        try:
            out[i] = str(int(out[i]) * n)
        except ValueError:
            raise SystemExit(f"train_scaling: --per-device {flag}: {opt} {out[i]!r} is not an integer") from None
    return out


def markdown(rows: list[dict], goal: float) -> str:
    one = rows[0] if rows[0]["devices"] == 1 else None

    def rate(r: dict, key: str) -> tuple[str, str]:
        """A rate and its multiple of one device's, as table cells."""
        v, base = r.get(key), one and one.get(key)
        return ("n/a" if v is None else f"{v:,.0f}"), (f"{v / base:.2f}" if v is not None and base else "n/a")

    lines = [f"| devices | control steps/s in training | x one device | after the first epoch | x one device | "
             f"minutes to {goal:.0%} held-out | held-out (eval) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        mins = "never" if r["minutes_to_goal"] is None else f"{r['minutes_to_goal']:.1f}"
        lines.append(f"| {r['devices']} | {' | '.join(rate(r, 'steps_per_second'))} | "
                     f"{' | '.join(rate(r, 'steady_steps_per_second'))} | {mins} | {r['held_out_success']:.1%} |")
    return "\n".join(lines + ["", f"{rows[0]['method']} from {rows[0]['obs_type']} on {rows[0]['device']}"]) + "\n"


def scaling_mode(per: list[str], rows: list[dict] = ()) -> str:
    """The mode the runs ran in, read from their own episode counts where each wrote one: a run made apart (a process
    a device, started by hand) records no per-device flags, and its collection was once labelled strong when it ran
    weak (notebook lead30). Runs that wrote none: the per-device flags declared."""
    envs = [(r["devices"], r.get("envs")) for r in rows]
    flags = f" ({', '.join('--' + f for f in per)} per device)" if per else ""
    if len(envs) > 1 and all(e for _, e in envs):
        if len({e / n for n, e in envs}) == 1:
            return f"weak: {envs[0][1] // envs[0][0]:,} episodes per device{flags}"
        if len({e for _, e in envs}) == 1:
            return f"strong: the one run's {envs[0][1]:,} episodes split over the devices{flags}"
        return "neither weak nor strong: " + ", ".join(f"{e:,} episodes on {n}" for n, e in envs) + flags
    return (f"weak: {', '.join('--' + f for f in per)} per device" if per
            else "strong: the one run's work split over the devices")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--devices", default="1,2,4", help="comma-separated device counts, one run each (default 1,2,4)")
    p.add_argument("--goal", type=float, required=True, help="the held-out rate to time (e.g. 0.95)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--per-device", default="", help="comma-separated train flags (e.g. envs,batch) given as one "
                   "device's share, multiplied by the device count (weak scaling; default: none, strong scaling)")
    p.add_argument("--collect", action="store_true", help="read the finished runs under --out, run none")
    args, train_args = p.parse_known_args(argv)
    train_args = [a for a in train_args if a != "--"]
    if any(a in ("--devices", "--out") for a in train_args):
        p.error("--devices and --out are this script's to set for each run")
    try:
        counts = [int(n) for n in args.devices.split(",")]
    except ValueError:
        p.error(f"--devices takes comma-separated integers, got {args.devices!r}")
    per = [f.strip().lstrip("-") for f in args.per_device.split(",") if f.strip()]
    earlier = args.out / "scaling.json"
    if args.collect and not train_args and earlier.is_file():
        # runs made apart (one process a count, side by side) each wrote the recipe they ran: their train arguments
        # and per-device flags are the collection's, so its scaling mode is the one they ran in
        try:
            made = json.loads(earlier.read_text())
            train_args, per = list(made["train_args"]), list(made["per_device"])
        except (OSError, ValueError, KeyError, TypeError) as e:
            p.error(f"--collect: {earlier} is not a scaling record this script wrote ({type(e).__name__}: {e}); "
                    "pass the runs' train arguments after -- instead")
    sized = {n: per_device(train_args, per, n) for n in counts} if not args.collect else {}  # checked before any run
    try:
        args.out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        p.error(f"--out {args.out}: {e.strerror}")
    rows, failed = [], []
    for n in counts:
        run = args.out / f"devices-{n}"
        finished = (run / "summary.json").is_file() and "eval" in json.loads((run / "summary.json").read_text())
        if not finished and not args.collect:
            cmd = [sys.executable, "-m", "mjx_pusht", "train", *sized[n], "--devices", str(n), "--out", str(run)]
            print("$", " ".join(cmd), flush=True)
            t = time.perf_counter()
            rc = subprocess.call(cmd)
            print(f"{n} devices: exit {rc} after {time.perf_counter() - t:.0f} s", flush=True)
        try:
            rows.append(measure(run, args.goal))
        except (OSError, KeyError, ValueError) as e:  # unreadable, cut or unfinished: listed, not dropped
            failed.append(f"{run} ({e})")
    atomic_write_json(args.out / "scaling.json", {"goal": args.goal, "train_args": train_args, "per_device": per,
                                                  "scaling": scaling_mode(per, rows), "runs": rows, "failed": failed})
    if rows:
        atomic_write_bytes(args.out / "scaling.md", (markdown(rows, args.goal) + scaling_mode(per, rows) + "\n").encode())
        print(markdown(rows, args.goal), end="")
    print("\n".join(f"failed: {f}" for f in failed), file=sys.stderr)
    return 0 if rows and not failed else 1


if __name__ == "__main__":
    raise SystemExit(main())
