"""lerobot-eval itself, timed: wall-clock, the share of it spent in the env (reset, step, render), and the success
rate with its Wilson 95% interval (over the episodes per_task lists).

    python -m benchmarks.lerobot_eval --policy POLICY_DIR --env pusht --episodes 500 --batch 500 --json out.json
    python -m benchmarks.lerobot_eval --policy POLICY_DIR --env mjx_pusht --episodes 500 --batch 500 --json out.json
    python -m benchmarks.lerobot_eval ... --env.episode_length=50     # any other argument goes to lerobot-eval

Runs LeRobot's own `lerobot.scripts.lerobot_eval.main` (the `lerobot-eval` console script, plugins
registered as it registers them) in this process with the arguments a user passes, after wrapping
`make_env` so that every vector env it builds counts the seconds spent in its `reset`, `step`
and `call` (`render`, and the attributes LeRobot reads each step). Nothing else of
LeRobot is changed. The policy is any `--policy.path` (e.g. tests/lerobot/tiny_policy.py's).
gym-pusht runs in LeRobot's SyncVectorEnv (`--eval.use_async_envs=false`: lerobot 0.6.1's
AsyncVectorEnv workers cannot find gym_pusht's env id, so its default fails for pusht), mjx_pusht
in one batch of `--batch` envs (the GPU's, where there is one). Images are 96 x 96 for both
(gym-pusht renders 96 whatever LeRobot's config says; the plugin is told so).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path


def _timed(env, clock: dict):
    """`env` with its reset, step and call timed into `clock`, patched on the instance (so LeRobot's
    isinstance checks, which pick how it renders, see the env's own class)."""

    def wrap(name, fn):
        def timed(*a, **k):
            key = "render" if name == "call" and a and a[0] == "render" else name
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                clock[key] = clock.get(key, 0.0) + time.perf_counter() - t

        return timed

    for name in ("reset", "step", "call"):
        setattr(env, name, wrap(name, getattr(env, name)))
    for sub in getattr(env, "envs", ()):  # SyncVectorEnv: LeRobot renders its first envs one by one
        sub.render = wrap("render", sub.render)
    return env


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, type=Path)
    p.add_argument("--env", choices=("pusht", "mjx_pusht"), required=True)
    p.add_argument("--episodes", type=int, default=500)
    p.add_argument("--batch", type=int, default=500)
    p.add_argument("--device", default="cuda")
    p.add_argument("--out", type=Path, default=Path("outputs/bench-lerobot-eval"))
    p.add_argument("--json", type=Path, default=None)
    a, extra = p.parse_known_args(argv)  # the rest go to lerobot-eval as they are, e.g. --env.episode_length=50
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    # the plugin registers mjx_pusht on import; imported here too, so it need not be pip-installed (a GPU
    # machine without a registry) for register_third_party_plugins to have found it
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "plugins" / "lerobot_env_mjx_pusht"))
    import lerobot_env_mjx_pusht  # noqa: F401
    import lerobot.envs as envs_pkg
    import lerobot.scripts.lerobot_eval as lerobot_eval

    clock: dict[str, float] = {}
    make_env = lerobot_eval.make_env

    def timed_make_env(*args, **kwargs):
        t = time.perf_counter()
        built = make_env(*args, **kwargs)
        clock["make_env"] = time.perf_counter() - t
        return {suite: {i: _timed(v, clock) for i, v in tasks.items()} for suite, tasks in built.items()}

    lerobot_eval.make_env = envs_pkg.make_env = timed_make_env
    out = a.out / f"{a.env}-{a.batch}-{int(time.time())}"
    args = [f"--policy.path={a.policy}", f"--policy.device={a.device}", "--policy.use_amp=false",
            f"--env.type={a.env}", f"--eval.n_episodes={a.episodes}", f"--eval.batch_size={a.batch}",
            "--eval.use_async_envs=false", f"--output_dir={out}", *extra]
    if a.env == "mjx_pusht":
        args += ["--env.observation_height=96", "--env.observation_width=96"]
    sys.argv = ["lerobot-eval", *args]
    t0 = time.perf_counter()
    lerobot_eval.main()
    wall = time.perf_counter() - t0
    whole = json.loads((out / "eval_info.json").read_text())
    info = whole["overall"]
    env_s = sum(v for k, v in clock.items() if k != "make_env")
    successes = sum(bool(s) for task in whole["per_task"] for s in task["metrics"]["successes"])
    from mjx_pusht.study.stats import wilson

    row = {"env": a.env, "episodes": info["n_episodes"], "batch": a.batch, "wall_s": wall, "eval_s": info["eval_s"],
           "env_s": env_s, "env_share_of_eval": env_s / info["eval_s"], "env_seconds": clock,
           "pc_success": info["pc_success"], "successes": successes,
           "wilson95_pc": [100 * x for x in wilson(successes, info["n_episodes"])],
           "avg_sum_reward": info["avg_sum_reward"], "lerobot_eval_args": args}
    print(json.dumps(row))
    if a.json:
        import torch

        row |= {"device": torch.cuda.get_device_name() if torch.cuda.is_available() else platform.processor(),
                "host": platform.node(), "date": time.strftime("%Y-%m-%d"), "cpus": os.cpu_count()}
        prev = json.loads(a.json.read_text()) if a.json.exists() else {}
        prev.setdefault("runs", []).append(row)
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(prev, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
