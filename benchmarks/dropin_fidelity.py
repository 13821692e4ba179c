"""The drop-in against gym-pusht itself: the same starts, the same actions, how far apart the blocks end.

    python -m benchmarks.dropin_fidelity [--episodes 1000] [--sources scripted,walk,expert]
        [--backend cpu|mjx-warp] [--workers 2] [--json benchmarks/results/cpu-dropin-fidelity.json]

gym-pusht 0.1.8 (pymunk) runs each episode closed loop: a driver reads gym-pusht's observation
and picks a pixel target, for `--steps` control steps (past a success too, so every episode has
all its actions). The drop-in (`mjx_pusht/PushT-gym-pusht-v0`, the batch of `gym.make_vec`, on
`--backend`: MuJoCo C, or MJX-Warp on a GPU) then starts every episode from the same
reset_to_state and replays the same actions. Three drivers, all in gym-pusht's pixels:

- `scripted`: gets behind the T and pushes it toward the goal, then turns it at the bar's end;
- `walk`: a random smooth walk of targets over the whole frame (it touches the T now and then);
- `expert`: this project's scripted expert (task/controllers.Expert, velocity commands in metres)
  on gym-pusht's observation converted to the world frame, each command made the pixel target
  its PD law tracks at that velocity (target = agent + velocity * kv / kp).

Per driver: the block pose error (body origin, pixels; angle, degrees) after 10, 50, 100 and 300
control steps, median, 90th percentile and max, over the episodes neither side has ended by then
(the drop-in stops an episode at its success, as gym-pusht's TimeLimit loop would); and per-episode
`is_success` agreement (succeeded within the episode on both or on neither). With `--closed-loop`
each driver also runs on the drop-in's own observations (the score a user would compare), and those
actions are replayed on gym-pusht (the same-actions agreement the other way round).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np

CHECKPOINTS = (10, 50, 100, 300)
SOURCES = ("scripted", "walk", "expert")
GOAL_COG = (256.0 - 45.0 * math.sin(math.pi / 4), 256.0 + 45.0 * math.cos(math.pi / 4))  # the goal T's centre of gravity
GOAL_ANGLE = math.pi / 4


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


class Scripted:
    """Push the T's centre of gravity toward the goal's; once there, turn it by pushing the bar's end.
    Pixels throughout; approaches go round the T on a circle that clears it (radius 100 about its centre)."""

    def __init__(self, seed: int):
        pass

    def __call__(self, obs, k):
        p, o, a = obs[0:2], obs[2:4], obs[4]
        c, s = math.cos(a), math.sin(a)
        cog = o + np.array([-s, c]) * 45.0

        def world(v):  # the T's frame (pymunk's: bar along x, stem along +y) to pixels
            return o + np.array([c * v[0] - s * v[1], s * v[0] + c * v[1]])

        d = np.array(GOAL_COG) - cog
        dist = float(np.linalg.norm(d))
        turn = float(_wrap(GOAL_ANGLE - a))
        if dist > 12.0 or abs(turn) < 0.05:  # translate: through the centre of gravity, toward the goal's
            u = d / max(dist, 1e-9)
            start, push = cog - u * 95.0, u
        else:  # turn: push the bar's end across it (the moment arm is 60 px about the centre of gravity)
            side = 1.0 if turn > 0 else -1.0
            start = world(np.array([50.0, -25.0 if side > 0 else 55.0]))
            push = world(np.array([0.0, side])) - world(np.zeros(2))
        rel = p - start
        along, lateral = rel @ push, rel @ np.array([-push[1], push[0]])
        if abs(lateral) < 8.0 and -8.0 < along < 120.0:  # in the lane: push on, pulling back onto its line
            return np.clip(p + push * 25.0 - np.array([-push[1], push[0]]) * lateral, 0.0, 512.0)
        r = p - cog
        ang_p, ang_s = math.atan2(r[1], r[0]), math.atan2(*(start - cog)[::-1])
        dphi = float(_wrap(ang_s - ang_p))
        if abs(dphi) < 0.35:
            return np.clip(start, 0.0, 512.0)
        step = float(np.clip(dphi, -0.6, 0.6))
        rad = 100.0 if np.linalg.norm(r) > 90.0 else float(np.linalg.norm(r)) + 20.0
        return np.clip(cog + rad * np.array([math.cos(ang_p + step), math.sin(ang_p + step)]), 0.0, 512.0)


class Walk:
    """A random smooth walk of targets: an Ornstein-Uhlenbeck velocity (px/step), kept inside the frame."""

    def __init__(self, seed: int):
        self.rng = np.random.default_rng([seed, 1])
        self.target, self.v = None, np.zeros(2)

    def __call__(self, obs, k):
        if self.target is None:
            self.target = obs[0:2].astype(np.float64)
        self.v = 0.8 * self.v + self.rng.normal(0.0, 6.0, 2)
        self.target = np.clip(self.target + self.v, 20.0, 492.0)
        self.v = np.where((self.target <= 20.0) | (self.target >= 492.0), -self.v, self.v)
        return self.target.copy()


class Expert:
    """task/controllers.Expert on gym-pusht's observation in the world frame; its velocity as the pixel
    target gym-pusht's PD law tracks at that velocity."""

    def __init__(self, seed: int):
        from mjx_pusht.task.controllers import Expert as E
        from mjx_pusht.task.controllers import seed_key

        self.ctrl, self.key = E(), seed_key([seed])
        self.carry = self.ctrl.init(self.key)

    def __call__(self, obs, k):
        from mjx_pusht.model import gym_pusht as frame
        from mjx_pusht.task.rules import observe

        agent = frame.to_world(np.asarray(obs[None, 0:2], np.float64))
        tee = frame.pose_to_world(np.asarray(obs[None, 2:4], np.float64), np.asarray(obs[None, 4], np.float64))
        v, self.carry = self.ctrl.act(self.carry, observe(agent, tee), k, self.key)
        return frame.to_px(agent + v * (frame.KV / frame.KP))[0]


DRIVERS = {"scripted": Scripted, "walk": Walk, "expert": Expert}


def run_gym_pusht(source: str, seeds, states, steps: int, actions=None) -> dict:
    """gym-pusht closed loop under `source`'s driver (or replaying `actions`): actions (N, steps, 2), block
    poses after each step (N, steps, 3: origin px, angle) and the first step (1-based) that reported
    is_success (0: none)."""
    from gym_pusht.envs.pusht import PushTEnv

    env = PushTEnv(obs_type="state")
    n = len(seeds)
    acts, poses, first = np.zeros((n, steps, 2)), np.zeros((n, steps, 3)), np.zeros(n, np.int64)
    cover = np.zeros((n, steps))
    for i, (seed, st) in enumerate(zip(seeds, states)):
        obs, _ = env.reset(options={"reset_to_state": st})
        drive = DRIVERS[source](int(seed))
        for k in range(steps):
            a = np.asarray(drive(obs, k) if actions is None else actions[i, k], np.float64)
            obs, _, _, _, info = env.step(a)
            acts[i, k] = a
            poses[i, k] = (*env.block.position, env.block.angle)
            cover[i, k] = info["coverage"]
            if info["is_success"] and not first[i]:
                first[i] = k + 1
    return {"actions": acts, "poses": poses, "first_success": first, "coverage": cover}


def _gym_part(args):
    return run_gym_pusht(*args)


def gym_pusht_pool(source: str, seeds, states, steps: int, workers: int, actions=None) -> dict:
    if workers <= 1:
        return run_gym_pusht(source, seeds, states, steps, actions)
    import multiprocessing

    idx = np.array_split(np.arange(len(seeds)), workers)
    parts = [(source, seeds[i], states[i], steps, None if actions is None else actions[i]) for i in idx]
    with multiprocessing.get_context("spawn").Pool(workers) as pool:
        outs = pool.map(_gym_part, parts)
    return {k: np.concatenate([o[k] for o in outs]) for k in outs[0]}


def run_dropin(states, actions, backend: str, source: str | None = None, seeds=None) -> dict:
    """The drop-in's batch from the same reset_to_state: under the same `actions` (N, steps, 2), or, given
    `source`, closed loop under that driver on its own observations (then the actions it took come back).
    Poses after each step, coverage, and the first step that terminated an episode (its is_success), 0 for none."""
    import gymnasium as gym

    import mjx_pusht  # noqa: F401  (registers the ids)

    n, steps = actions.shape[:2]
    env = gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=n, backend=backend, obs_type="state",
                       autoreset_mode="disabled", max_episode_steps=steps + 1, array_type="numpy")
    obs, _ = env.reset(options={"reset_to_state": states})
    drivers = None if source is None else [DRIVERS[source](int(s)) for s in seeds]
    poses, first, cover = np.zeros((n, steps, 3)), np.zeros(n, np.int64), np.zeros((n, steps))
    taken = np.zeros((n, steps, 2))
    for k in range(steps):
        if drivers is None:
            a = actions[:, k]
        else:
            o = np.asarray(obs, np.float64)
            a = np.array([d(o[i], k) for i, d in enumerate(drivers)], np.float64)
        obs, _, term, _, info = env.step(a)
        taken[:, k] = a
        poses[:, k] = np.asarray(obs, np.float64)[:, 2:5]
        cover[:, k] = np.asarray(info["coverage"], np.float64)
        succ = np.asarray(info["is_success"], bool)
        first[(first == 0) & succ] = k + 1
    env.close()
    return {"poses": poses, "first_success": first, "coverage": cover, "actions": taken}


def compare(ref: dict, ours: dict, checkpoints=CHECKPOINTS) -> dict:
    """Pose errors at each checkpoint over the episodes live on both sides, and is_success agreement."""
    out = {}
    steps = ref["poses"].shape[1]
    for k in checkpoints:
        if k > steps:
            continue
        live = ((ref["first_success"] == 0) | (ref["first_success"] >= k)) & \
               ((ours["first_success"] == 0) | (ours["first_success"] >= k))
        d = ours["poses"][live, k - 1] - ref["poses"][live, k - 1]
        px = np.hypot(d[:, 0], d[:, 1])
        deg = np.degrees(np.abs(_wrap(d[:, 2])))
        stat = (lambda x: {"median": float(np.median(x)), "p90": float(np.percentile(x, 90)), "max": float(x.max())}
                if len(x) else None)
        out[f"after_{k}"] = {"episodes": int(live.sum()), "px": stat(px), "deg": stat(deg)}
    out["is_success"] = success_agreement(ref, ours)
    return out


def success_agreement(ref: dict, ours: dict) -> dict:
    """Per episode: did it succeed (within its steps) on both sides, or on neither; for the episodes that
    part, the best coverage the failing side reached (how near the 0.95 line it came)."""
    a, b = ref["first_success"] > 0, ours["first_success"] > 0
    out = {"gym_pusht_rate": float(a.mean()), "dropin_rate": float(b.mean()), "agreement": float((a == b).mean()),
           "both": int((a & b).sum()), "gym_pusht_only": int((a & ~b).sum()), "dropin_only": int((~a & b).sum())}
    both = a & b
    if both.any():
        out["step_difference_median"] = float(np.median(np.abs(ref["first_success"][both] - ours["first_success"][both])))
    parted = np.concatenate([ours["coverage"][a & ~b].max(axis=1), ref["coverage"][~a & b].max(axis=1)])
    if len(parted):
        out["parted_best_coverage"] = {"median": float(np.median(parted)), "min": float(parted.min())}
    return out


def goals(row: dict) -> dict:
    """The issue's goals on the scripted pusher: after 50 steps within 1 px / 1 deg (median) and 5 px / 5 deg
    (90th percentile); is_success agreeing on at least 98% of episodes."""
    k = row["after_50"]
    return {"median_within_1px_1deg": k["px"]["median"] <= 1 and k["deg"]["median"] <= 1,
            "p90_within_5px_5deg": k["px"]["p90"] <= 5 and k["deg"]["p90"] <= 5,
            "success_agreement_98": row["is_success"]["agreement"] >= 0.98}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=1000, help="episodes per driver (gym-pusht's resets of seeds 0..)")
    p.add_argument("--steps", type=int, default=300, help="control steps per episode")
    p.add_argument("--sources", default=",".join(SOURCES), help=f"drivers, comma-separated: {', '.join(SOURCES)}")
    p.add_argument("--episodes-per-source", default="", help="override per driver, e.g. walk=200,expert=200")
    p.add_argument("--backend", default="cpu", choices=("cpu", "mjx-warp"), help="the drop-in's backend")
    p.add_argument("--workers", type=int, default=1, help="processes running gym-pusht")
    p.add_argument("--closed-loop", action="store_true", help="also run each driver on the drop-in's own "
                   "observations and compare its is_success per episode with gym-pusht's")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    sources = [s for s in args.sources.split(",") if s]
    bad = [s for s in sources if s not in SOURCES]
    if bad or args.episodes < 1 or args.steps < 1:
        print(f"dropin_fidelity: unknown driver(s) {bad}; choose from {', '.join(SOURCES)}" if bad else
              "dropin_fidelity: --episodes and --steps must be positive", file=sys.stderr)
        return 2
    per = {s: args.episodes for s in sources}
    for item in filter(None, args.episodes_per_source.split(",")):
        name, _, n = item.partition("=")
        per[name] = int(n)
    from mjx_pusht.model.gym_pusht import reset_state

    rows = {}
    for source in sources:
        seeds = np.arange(per[source])
        states = np.array([reset_state(int(s)) for s in seeds])  # gym-pusht's reset(seed=s) draws
        t0 = time.perf_counter()
        ref = gym_pusht_pool(source, seeds, states, args.steps, args.workers)
        t1 = time.perf_counter()
        ours = run_dropin(states, ref["actions"], args.backend)
        t2 = time.perf_counter()
        row = {"episodes": len(seeds), "steps": args.steps, **compare(ref, ours)}
        if args.closed_loop:  # each side under the driver on its own observations: do the scores agree?
            own = run_dropin(states, ref["actions"], args.backend, source, seeds)
            row["closed_loop_is_success"] = success_agreement(ref, own)
            # and the other way round: the drop-in's own actions replayed on gym-pusht (is the same-actions
            # agreement the driver's, whichever side chose them?)
            back = gym_pusht_pool(source, seeds, states, args.steps, args.workers, own["actions"])
            row["dropin_actions_on_gym_pusht_is_success"] = success_agreement(back, own)
        row["seconds"] = {"gym_pusht": round(t1 - t0, 1), "dropin_replay": round(t2 - t1, 1),
                          "dropin_closed_loop": round(time.perf_counter() - t2, 1) if args.closed_loop else None}
        if source == "scripted":
            row["goals"] = goals(row)
        rows[source] = row
        print(json.dumps({source: row}), flush=True)
    if args.json:
        from mjx_pusht.backends.base import versions

        out = {"command": "python -m benchmarks.dropin_fidelity " + " ".join(argv if argv is not None else sys.argv[1:]),
               "device": f"CPU, {os.cpu_count()} cores ({platform.processor() or platform.machine()})"
               + ("" if args.backend == "cpu" else " + the GPU MJX-Warp runs on"),
               "backend": args.backend, "host": platform.node(), "date": time.strftime("%Y-%m-%d"),
               "versions": versions(), "checkpoints": list(CHECKPOINTS), "sources": rows}
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
