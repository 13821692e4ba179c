"""The gym-pusht drop-in's batch on MJX-Warp against the same batch on MuJoCo C (needs a GPU).

    OUT=benchmarks/results python benchmarks/dropin_check.py   # writes $OUT/dropin-check.json

64 envs, `state`, seed 0, 25 steps of the same random pixel targets in [100, 412], same-step
autoreset: the largest difference per step in the agent's and the block's pixel positions
(float32 on the GPU, float64 on the CPU) and how many success flags differ.
"""
import json
import os

import gymnasium as gym
import numpy as np

import mjx_pusht  # noqa: F401  (registers the env ids)

n = 64
out = {}
acts = np.random.default_rng(0).uniform(100, 412, (25, n, 2))
res = {}
for be in ("cpu", "mjx-warp"):
    e = gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=n, backend=be, obs_type="state", autoreset_mode="same_step")
    o, i = e.reset(seed=0)
    traj = []
    for a in acts:
        o, r, te, tr, i = e.step(a)
        traj.append((np.asarray(i["pos_agent"]), np.asarray(i["block_pose"]), np.asarray(i["is_success"])))
    res[be] = traj
for k, name in enumerate(["agent_px", "block_px"]):
    d = [np.abs(a[k] - b[k])[..., :2].max() for a, b in zip(res["cpu"], res["mjx-warp"])]
    out[name + "_max_diff_by_step"] = [float(x) for x in d]
out["success_flags_differ"] = int(sum((a[2] != b[2]).sum() for a, b in zip(res["cpu"], res["mjx-warp"])))
print(json.dumps(out))
with open(os.environ.get("OUT", ".") + "/dropin-check.json", "w") as f:
    json.dump(out, f, indent=1)
