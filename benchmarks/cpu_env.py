"""One env on one CPU core, as most PushT users run it: mjx_pusht's two ids beside gym-pusht, in one run.

Env steps per second, state observations unless named, pinned to one core (and one BLAS/torch
thread), for `mjx_pusht/PushT-v0`, the drop-in `mjx_pusht/PushT-gym-pusht-v0` and gym-pusht 0.1.8:

- `bare`: `env.step` in a loop (a reset where an episode ends), through `gym.make`'s wrappers;
- `sb3_dummy_x1` / `sb3_dummy_x4`: SB3's `DummyVecEnv` of 1 and 4 envs stepped with random actions;
- `sb3_ppo_x4`: SB3 PPO learning on a `DummyVecEnv` of 4 (env steps per second of `learn`, updates included);
- `pixels_bare`: the bare loop with `obs_type="pixels"` at 96 x 96 (gym-pusht's and the drop-in's default);
- `mj_step_limit`: the scene's bare `mj_step` x frame_skip, the physics' own rate of control steps (the limit).

Each case runs `--repeats` times (PPO: 3 at most), the ids interleaved (repeat r runs every id back to back, so a shared
machine's drifting load slows them alike), and reports the median and every repeat. Writes
benchmarks/results/cpu-env.json with the machine named.

    python -m benchmarks.cpu_env            # a few minutes on one core
    python -m benchmarks.cpu_env --quick    # a smoke run (seconds), no result file
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import mjx_pusht  # noqa: E402,F401  (first: it picks MuJoCo's headless GL before anything imports mujoco)

RESULTS = Path(__file__).parent / "results"
IDS = {"PushT-v0": "mjx_pusht/PushT-v0", "drop-in": "mjx_pusht/PushT-gym-pusht-v0", "gym-pusht": "gym_pusht/PushT-v0"}


def machine() -> dict:
    info = Path("/proc/cpuinfo")
    model = next((line.split(":", 1)[1].strip() for line in info.read_text().splitlines()
                  if line.startswith("model name")), "") if info.exists() else platform.processor()
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent).stdout.strip()
    except OSError:
        commit = ""
    return {"cpu": model, "cores_visible": os.cpu_count(), "pinned_to_core": sorted(os.sched_getaffinity(0)),
            "load_average_at_start": os.getloadavg(), "python": platform.python_version(),
            "platform": platform.platform(), "commit": commit}


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("mujoco", "gymnasium", "gym-pusht", "pymunk", "stable-baselines3", "torch", "numpy"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


def make(name: str, **kw):
    import gymnasium as gym

    import mjx_pusht  # noqa: F401  (registers the ids)

    if name == "gym-pusht":
        import gym_pusht  # noqa: F401
    return gym.make(IDS[name], **kw)


def _actions(space, n: int, seed: int = 0) -> np.ndarray:
    space.seed(seed)
    return np.stack([space.sample() for _ in range(n)])


def bare(name: str, steps: int, **kw) -> float:
    env = make(name, **kw)
    acts = _actions(env.action_space, steps)
    env.reset(seed=0)
    for a in acts[:20]:  # warm up (the first image makes the GL context)
        env.step(a)
    env.reset(seed=0)
    t0 = time.perf_counter()
    for a in acts:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - t0)
    env.close()
    return rate


def sb3_dummy(name: str, n: int, steps: int) -> float:
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: make(name) for _ in range(n)])
    venv.seed(0)
    venv.reset()
    acts = _actions(venv.action_space, steps // n)
    t0 = time.perf_counter()
    for a in acts:
        venv.step(np.repeat(a[None], n, axis=0))
    rate = (len(acts) * n) / (time.perf_counter() - t0)
    venv.close()
    return rate


def sb3_ppo(name: str, steps: int) -> float:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: make(name) for _ in range(4)])
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=256, n_epochs=4, seed=0, device="cpu", verbose=0)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    rate = model.num_timesteps / (time.perf_counter() - t0)
    venv.close()
    return rate


def mj_step_limit(seconds: float) -> dict:
    """The scene's own mj_step on one core: physics steps/s and the control steps/s they allow (frame_skip 10)."""
    import mujoco

    from mjx_pusht.backends.cpu import cpu_model
    from mjx_pusht.scenario import Scenario

    model = cpu_model(Scenario())
    data = mujoco.MjData(model)
    data.ctrl[:] = 0.3
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        mujoco.mj_step(model, data, nstep=1000)
        n += 1000
        mujoco.mj_resetData(model, data)
        data.ctrl[:] = 0.3
    rate = n / (time.perf_counter() - t0)
    return {"mj_step_per_s": rate, "control_steps_per_s": rate / 10, "us_per_mj_step": 1e6 / rate}


def _median(fn, repeats: int) -> dict:
    runs = [fn() for _ in range(repeats)]
    return {"median": statistics.median(runs), "runs": runs}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="a smoke run: few steps, one repeat, no result file")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--core", type=int, default=None, help="the core to pin to (default: the last one allowed)")
    p.add_argument("--out", default=str(RESULTS / "cpu-env.json"))
    p.add_argument("--skip-ppo", action="store_true", help="leave out SB3 PPO learning (the slowest case)")
    args = p.parse_args(argv)
    if args.repeats < 1:
        p.error(f"--repeats must be at least 1, got {args.repeats}")
    core = args.core if args.core is not None else max(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {core})
    import torch

    torch.set_num_threads(1)
    q = args.quick
    repeats = 1 if q else args.repeats
    steps, ppo_steps = (300, 1024) if q else (1500, 4096)
    out = {"machine": machine(), "versions": _versions(), "units": "env steps per second (one core)",
           "steps_per_case": steps, "ppo_timesteps": ppo_steps, "repeats": repeats, "cases": {}}
    cases = {"bare": lambda name: bare(name, steps),
             "sb3_dummy_x1": lambda name: sb3_dummy(name, 1, steps),
             "sb3_dummy_x4": lambda name: sb3_dummy(name, 4, steps),
             "pixels_bare": lambda name: bare(name, steps // 3, obs_type="pixels")}
    if not args.skip_ppo:
        cases["sb3_ppo_x4"] = lambda name: sb3_ppo(name, ppo_steps)
    # Interleaved: repeat r of a case runs every id back to back, so a machine whose load drifts (a shared
    # one) slows the ids alike, and the ids' ratios hold where their absolute rates do not.
    runs = {name: {case: [] for case in cases} for name in IDS}
    limit = []
    for case, fn in cases.items():
        for _ in range(min(3, repeats) if case == "sb3_ppo_x4" else repeats):
            limit.append(mj_step_limit(0.3 if q else 1.0))
            for name in IDS:
                runs[name][case].append(fn(name))
        print(case, {name: round(statistics.median(runs[name][case])) for name in IDS}, flush=True)
    out["cases"]["mj_step_limit"] = {k: statistics.median(x[k] for x in limit) for k in limit[0]}
    out["cases"]["mj_step_limit"]["runs_us_per_mj_step"] = [x["us_per_mj_step"] for x in limit]
    for name in IDS:
        out["cases"][name] = {case: {"median": statistics.median(r), "runs": r} for case, r in runs[name].items()}
    lim = out["cases"]["mj_step_limit"]
    print("mj_step limit:", round(lim["control_steps_per_s"]), "control steps/s",
          f"({lim['us_per_mj_step']:.2f} us per mj_step)")
    c = out["cases"]
    med = {k: {case: v["median"] for case, v in row.items()} for k, row in c.items() if k in IDS}
    out["goals"] = {
        "PushT-v0 bare >= 10,000": med["PushT-v0"]["bare"] >= 10_000,
        "drop-in bare >= 10,000": med["drop-in"]["bare"] >= 10_000,
        "PushT-v0 bare >= 2x gym-pusht": med["PushT-v0"]["bare"] >= 2 * med["gym-pusht"]["bare"],
        "drop-in bare >= 2x gym-pusht": med["drop-in"]["bare"] >= 2 * med["gym-pusht"]["bare"],
        "PushT-v0 pixels >= gym-pusht pixels": med["PushT-v0"]["pixels_bare"] >= med["gym-pusht"]["pixels_bare"],
        "drop-in pixels >= gym-pusht pixels": med["drop-in"]["pixels_bare"] >= med["gym-pusht"]["pixels_bare"],
    }
    print(json.dumps(out["goals"], indent=1))
    if not q:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=1) + "\n")
        print("wrote", args.out)
    return out


if __name__ == "__main__":
    main()
