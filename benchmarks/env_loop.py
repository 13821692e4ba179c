"""The environment in a user's loop, against the raw physics, side by side in one process per batch size.

    python -m benchmarks.env_loop --envs 4096,16384,65536,131072 [--obs state] [--steps 50] [--json out.json]
    python -m benchmarks.env_loop --envs 4096,16384 --obs pixels
    python -m benchmarks.env_loop --envs 16384 --obs pixels --cases raw,scan_autoreset --ends 10
    python -m benchmarks.env_loop --envs 16384,65536 --cases scan_autoreset,scan_autoreset_randomized \
        --randomize tee_mass=0.5:2,tee_damping=0.5:1.5,tee_frictionloss=0.1:2,kv=0.8:1.2

For each N (one process each, so that one size failing to fit is recorded, not fatal), on MJX-Warp:
- `raw`: the physics alone: a jitted scan of `steps` control steps, each 10 `mjx.step`s of all N
  worlds at the JAX policy's ctrl (no task, no reset, no env observation), from the same start poses
  as the env's (seeds 0..N-1): the ceiling, the same physics as `scan_autoreset` steps;
- `raw_zero_pose`: the raw case as measured before notebook change 22: every world from one pose (tee
  and pusher at the origin) at random actions: different physics, kept to compare old figures;
- `scan_autoreset`: the env (`wrappers.AutoReset(PushTEnv)`, same-step autoreset, start poses from
  the device pool) stepped in a jitted scan by a JAX policy (a fixed random linear layer + tanh on
  the observation), with pixels rendered in the step for `--obs pixels`, its episodes `--ends` control
  steps long so that every row ends and resets in the timed steps (5 times in 50): the rate with resets
  in it (with the task's 300-step episodes, 30 timed steps would reset nothing);
- `scan_autoreset_randomized`: the same loop with physics drawn per episode (`PushTEnv(randomize=...)`, the
  `--randomize` ranges, each reset drawing its episode's from the pool), reported with `fraction_of_fixed`, its
  rate over `scan_autoreset`'s in the same process (the goal: at least 0.9); `scan_autoreset_goals` a
  goal drawn per episode (`goal="random"`: its pose observed, reward and success against it; with pixels, the
  target drawn at it), `scan_autoreset_goals_randomized` both;
- `gym_torch`: `gym.make_vec("mjx_pusht/PushT-v0", num_envs=N, array_type="torch",
  autoreset_mode="same_step")` stepped from Python by a torch policy on the same GPU (observations
  reach torch through DLPack); `gym_torch_next_step` the same in gymnasium's default mode, next_step
  (with pixels, same_step renders twice a step: the ended episodes' last images for `final_obs`);
- `gym_numpy`: the same vector env with `array_type="numpy"` and NumPy actions (copies to the host);
- `dropin_numpy` / `dropin_torch`: the gym-pusht drop-in's vector env
  (`gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", ...)`, `pixels_agent_pos` with `--obs pixels`),
  random pixel targets, NumPy out (its default, what a gym-pusht loop reads) or torch tensors.
- `*_two_renders` (`gym_torch_two_renders`, `gym_torch_two_renders_ends`, `dropin_torch_two_renders`):
  same_step with pixels as it ran before docs/notebook/samestep.md, rendering every world twice a step, beside the
  default (one render, the new episodes' first images from the start pool); `dropin_torch_follow`: the
  drop-in driven by small target moves from its observations, not targets anywhere in the frame.
- `*_ends` (`gym_torch_ends`, `gym_numpy_ends`, `dropin_numpy_ends`,
  `dropin_torch_ends`): the same loops with episodes of `--ends` control steps (default 10), so every
  row ends and restarts several times in the timed steps (5 times in 50): the rate with resets in it.
Every env case reports `episodes_reset`, the episodes that ended (and so were reset) in the timed steps.
Each figure is N x steps / seconds after one warm-up (compile) call or 3 warm-up steps, timed until
the results are ready on the device. Memory: the GPU's used bytes (nvidia-smi, every allocator:
XLA, Warp, torch) after each case, and JAX's peak bytes in use.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

ONE = r"""
import json, os, subprocess, sys, time
import numpy as np
n, steps, obs_kind, cases, ends = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4].split(","), int(sys.argv[5])
randomize, env_backend = sys.argv[6], sys.argv[7]
import jax, jax.numpy as jnp
import mjx_pusht
from mujoco import mjx
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.wrappers import AutoReset
from mjx_pusht.model.randomize import parse as parse_randomize
from mjx_pusht.task.episode import Episode

pixels = 96 if obs_kind == "pixels" else 0
row = {"envs": n, "obs": obs_kind, "steps": steps, "ends": ends, "graph_mode": os.environ.get("MJX_PUSHT_ENV_GRAPH_MODE") or "default"}

def gpu_used():
    try:
        out = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                             capture_output=True, text=True).stdout
        return int(out.split()[0]) * 2**20
    except Exception:
        return None

def record(name, seconds, extra=None):
    stats = jax.devices()[0].memory_stats() or {}
    row[name] = {"seconds": seconds, "control_steps_per_s": n * steps / seconds, "ms_per_step": 1000 * seconds / steps,
                 "gpu_used_bytes": gpu_used(), "jax_peak_bytes": stats.get("peak_bytes_in_use"), **(extra or {})}
    print(json.dumps({name: row[name]}), file=sys.stderr, flush=True)

def attempt(name, fn):
    try:
        fn()
    except Exception as e:
        row[name] = {"error": f"{type(e).__name__}: {str(e).splitlines()[0][:300]}", "gpu_used_bytes": gpu_used()}
        print(json.dumps({name: row[name]}), file=sys.stderr, flush=True)

TDEV = "cuda" if jax.devices()[0].platform == "gpu" else "cpu"  # torch's device: the GPU's, or the CPU in a smoke test
env = PushTEnv(backend=env_backend, pixels=pixels)
row["graph_mode"] = env.graph_mode or "MJX default"  # the mode the env resolved (MJX_PUSHT_ENV_GRAPH_MODE overrides)
W = jax.random.normal(jax.random.PRNGKey(0), (5, 2)) * 0.5

def raw():
    # the env's own worlds (its reset's start poses for seeds 0..n-1, as scan_autoreset starts) under the same
    # policy, the observation read off qpos: the same physics as the env steps, without the env around it
    from mjx_pusht.task.reset import start_poses
    mx, d0, lay = env._mx, env.template(n), env.layout
    q0 = lay.initial_qpos(env.model, start_poses(np.arange(n), reset=env.reset_kind))
    # committed to the device as the jitted run's outputs are, so the timed call reuses the first call's program
    d = jax.device_put(jax.vmap(lambda q: d0.replace(qpos=q))(jnp.asarray(q0, env.runner.dtype)), jax.devices()[0])
    def ctrl_step(d):
        u = jnp.tanh(jnp.concatenate([lay.pusher_xy(d.qpos), lay.tee_pose(d.qpos)]) @ W)
        def phys(d, _):
            return mjx.step(mx, d.replace(ctrl=u)), None
        return jax.lax.scan(phys, d, None, env.episode.frame_skip)[0]
    vstep = jax.vmap(ctrl_step)
    @jax.jit
    def run(d):
        return jax.lax.scan(lambda d, _: (vstep(d), None), d, None, steps)[0]
    d1 = jax.block_until_ready(run(d))
    t0 = time.perf_counter(); jax.block_until_ready(run(d1)); record("raw", time.perf_counter() - t0)
    row["raw"]["compiles"] = run._cache_size()  # 1: the timed call ran the program compiled by the first

def raw_zero_pose():
    # the raw case before notebook change 22: every world from one pose (tee and pusher at the origin), random
    # actions; other physics than the env's worlds step, kept to compare with the figures measured with it
    mx, d0 = env._mx, env.template(n)
    d = jax.vmap(lambda q: d0.replace(qpos=q))(jnp.asarray(env.layout.initial_qpos(env.model, np.zeros((n, 5))), jnp.float32))
    def ctrl_step(d, u):
        def phys(d, _):
            return mjx.step(mx, d.replace(ctrl=u)), None
        return jax.lax.scan(phys, d, None, env.episode.frame_skip)[0]
    vstep = jax.vmap(ctrl_step)
    @jax.jit
    def run(d, key):
        def body(d, k):
            u = jax.random.uniform(k, (n, 2), minval=-1, maxval=1)
            return vstep(d, u), None
        return jax.lax.scan(body, d, jax.random.split(key, steps))[0]
    jax.block_until_ready(run(d, jax.random.PRNGKey(1)))
    t0 = time.perf_counter(); jax.block_until_ready(run(d, jax.random.PRNGKey(2))); record("raw_zero_pose", time.perf_counter() - t0)

def scan_autoreset(max_steps, name="scan_autoreset", spec=None, goal="fixed"):
    e = PushTEnv(backend=env_backend, pixels=pixels, episode=Episode(max_steps=max_steps), randomize=spec, goal=goal)
    ar = AutoReset(e, mode="same_step")
    s = ar.reset(np.arange(n))
    @jax.jit
    def run(s):
        def body(s, _):
            a = jnp.tanh(s.obs["state"] @ W)
            return ar.step(s, a), s.reward
        return jax.lax.scan(body, s, None, steps)
    s1, _ = jax.block_until_ready(run(s))
    s1 = jax.block_until_ready(ar.refill(s1))  # fresh start queues: the warm-up's resets used them up
    t0 = time.perf_counter(); s2, r = jax.block_until_ready(run(s1)); dt = time.perf_counter() - t0
    e.check(s2)
    ended = int(np.asarray(s2.info["used"]).sum()) - int(np.asarray(s1.info["used"]).sum())
    # compiles 1: the timed call reused the first call's program (change 13's timed call compiled a second one)
    record(name, dt, {"episodes_reset": ended, "max_resets_per_row": int(np.asarray(s2.info["used"]).max()),
                                  "compiles": run._cache_size()})

def two_renders(envs, on):
    # the same-step pixel step as it was before docs/notebook/samestep.md: every world rendered twice a step (the ended
    # episodes' last images, then every image again after the merge) instead of the new starts' from the pool
    if on:
        envs._ar.image_pool = False
    return "_two_renders" if on else ""

def gym_loop(array_type, mode="same_step", max_steps=None, twice=False):
    import gymnasium as gym
    envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=n, backend="mjx-warp", obs_type="state" if not pixels else "pixels_agent_pos",
                        array_type=array_type, autoreset_mode=mode, max_episode_steps=max_steps or 300)
    tag = two_renders(envs, twice)
    obs, _ = envs.reset(seed=0)
    if array_type == "torch":
        import torch
        Wt = torch.as_tensor(np.asarray(W), device=TDEV)
        def act(obs):
            x = obs if not pixels else torch.cat([obs["agent_pos"], obs["agent_pos"], obs["agent_pos"][:, :1]], 1)
            return torch.tanh(x @ Wt)
        sync = torch.cuda.synchronize if TDEV == "cuda" else (lambda: None)
    else:
        rng = np.random.default_rng(0)
        acts = [rng.uniform(-1, 1, (n, 2)).astype(np.float32) for _ in range(4)]
        act = lambda obs, i=[0]: acts[(i.__setitem__(0, i[0] + 1) or i[0]) % 4]
        sync = lambda: None
    for _ in range(3):
        obs, r, te, tr, info = envs.step(act(obs))
    sync(); jax.block_until_ready(envs.unwrapped._state.reward) if hasattr(envs, "unwrapped") else None
    ended = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        obs, r, te, tr, info = envs.step(act(obs))
        ended = ended + (te | tr).sum()
    sync(); jax.block_until_ready(envs._state.reward)
    record("gym_" + array_type + ("" if mode == "same_step" else "_" + mode) + tag + ("" if max_steps is None else "_ends"),
           time.perf_counter() - t0, {"output": type(r).__module__.split(".")[0], "autoreset_mode": mode,
                                      "episodes_reset": int(ended)})
    envs.close()

def dropin(array_type, max_steps=None, twice=False, follow=False):
    # follow: targets a policy's small moves away from the pusher (as gym_torch's policy moves it), not targets
    # drawn anywhere in the 512 px frame each step: the same env under gentler physics
    import gymnasium as gym
    envs = gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=n, backend="mjx-warp",
                        obs_type="pixels_agent_pos" if pixels else "state", array_type=array_type,
                        autoreset_mode="same_step", max_episode_steps=max_steps or 300)
    tag = two_renders(envs, twice) + ("_follow" if follow else "")
    obs, _ = envs.reset(seed=0)
    rng = np.random.default_rng(0)
    acts = [rng.uniform(0, 512, (n, 2)).astype(np.float32) for _ in range(4)]
    if array_type == "torch":
        import torch
        acts = [torch.as_tensor(a, device=TDEV) for a in acts]
        Wt = torch.as_tensor(np.asarray(W), device=TDEV)
    def act(obs, i):
        if not follow:
            return acts[i % 4]
        p = obs["agent_pos"] if pixels else obs[:, :2]
        x = torch.cat([p, p, p[:, :1]], 1) / 512
        return p + 20 * torch.tanh(x @ Wt)  # up to 20 px (4 cm) a control step
    for i in range(3):
        obs, *_ = envs.step(act(obs, i))
    jax.block_until_ready(envs._state.reward)
    ended = 0
    t0 = time.perf_counter()
    for i in range(steps):
        obs, r, te, tr, info = envs.step(act(obs, i))
        ended = ended + (te | tr).sum()
    if array_type == "torch" and TDEV == "cuda":
        torch.cuda.synchronize()
    jax.block_until_ready(envs._state.reward)
    record("dropin_" + array_type + tag + ("" if max_steps is None else "_ends"), time.perf_counter() - t0,
           {"output": type(r).__module__.split(".")[0], "episodes_reset": int(ended)})
    envs.close()

for c in cases:
    attempt(c, {"raw": raw, "raw_zero_pose": raw_zero_pose, "scan_autoreset": lambda: scan_autoreset(ends),
                "scan_autoreset_randomized": lambda: scan_autoreset(ends, "scan_autoreset_randomized",
                                                                    parse_randomize(randomize)),
                "scan_autoreset_goals": lambda: scan_autoreset(ends, "scan_autoreset_goals", goal="random"),
                "scan_autoreset_goals_randomized": lambda: scan_autoreset(ends, "scan_autoreset_goals_randomized",
                                                                          parse_randomize(randomize), "random"),
                "gym_torch": lambda: gym_loop("torch"), "gym_torch_next_step": lambda: gym_loop("torch", "next_step"),
                "gym_numpy": lambda: gym_loop("numpy"), "dropin_numpy": lambda: dropin("numpy"),
                "dropin_torch": lambda: dropin("torch"), "gym_torch_ends": lambda: gym_loop("torch", max_steps=ends),
                "gym_numpy_ends": lambda: gym_loop("numpy", max_steps=ends),
                "dropin_numpy_ends": lambda: dropin("numpy", ends), "dropin_torch_ends": lambda: dropin("torch", ends),
                "gym_torch_two_renders": lambda: gym_loop("torch", twice=True),
                "gym_torch_two_renders_ends": lambda: gym_loop("torch", max_steps=ends, twice=True),
                "dropin_torch_two_renders": lambda: dropin("torch", twice=True),
                "dropin_torch_follow": lambda: dropin("torch", follow=True)}[c])
if "raw" in row and "control_steps_per_s" in row["raw"]:
    for c in cases:
        if c != "raw" and "control_steps_per_s" in row.get(c, {}):
            row[c]["fraction_of_raw"] = row[c]["control_steps_per_s"] / row["raw"]["control_steps_per_s"]
fixed = row.get("scan_autoreset", {})
for c in ("scan_autoreset_randomized", "scan_autoreset_goals", "scan_autoreset_goals_randomized"):
    drawn = row.get(c, {})
    if "control_steps_per_s" in fixed and "control_steps_per_s" in drawn:
        drawn["fraction_of_fixed"] = drawn["control_steps_per_s"] / fixed["control_steps_per_s"]
print(json.dumps(row))
"""

CASES = "raw,raw_zero_pose,scan_autoreset,gym_torch,gym_torch_next_step,gym_numpy"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--envs", default="4096,16384,65536,131072")
    p.add_argument("--obs", default="state", choices=["state", "pixels"])
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--cases", default=CASES)
    p.add_argument("--ends", type=int, default=10,
                   help="control steps an episode in scan_autoreset and the *_ends cases (default 10: 5 resets a row in 50 steps)")
    p.add_argument("--randomize", default="tee_mass=0.5:2,tee_damping=0.5:1.5,tee_frictionloss=0.1:2,kv=0.8:1.2",
                   help="scan_autoreset_randomized's ranges, as mjx-pusht's --randomize (model/randomize.py)")
    p.add_argument("--backend", default="mjx-warp", choices=["mjx-warp", "mjx-jax"],
                   help="scan_autoreset's env backend (mjx-jax: a CPU check of the command; the figures are MJX-Warp's)")
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    rows = []
    for n in (int(x) for x in args.envs.split(",")):
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-c", ONE, str(n), str(args.steps), args.obs, args.cases, str(args.ends),
                            args.randomize, args.backend],
                           capture_output=True, text=True)
        try:
            row = json.loads(r.stdout.strip().splitlines()[-1])
        except (IndexError, json.JSONDecodeError):
            row = {"envs": n, "obs": args.obs, "error": ((r.stderr.strip().splitlines() or ["?"])[-1])[:300]}
        row["process_seconds"] = time.perf_counter() - t0
        rows.append(row)
        print(json.dumps(row), flush=True)
    if args.json:
        import jax

        from mjx_pusht.backends.base import versions

        d = jax.devices()[0]
        out = {"command": "python -m benchmarks.env_loop " + " ".join(argv if argv is not None else sys.argv[1:]),
               "device": getattr(d, "device_kind", d.platform), "host": platform.node(),
               "date": time.strftime("%Y-%m-%d"), "versions": versions(), "rows": rows}
        prev = json.load(open(args.json)) if os.path.exists(args.json) else {}
        prev.setdefault("runs", []).append(out)
        with open(args.json, "w") as f:
            json.dump(prev, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
