"""Where the env step's time goes on the GPU: the same step scanned in one jitted program or called once a step.

    python benchmarks/env_bisect.py N STEPS physics_only,plain,full,percall_plain,percall_full [PIXELS]
    python benchmarks/env_bisect.py 16384 30 full,percall_full,percall_final,percall_render,gym_jax,gym_torch 96
    python benchmarks/env_bisect.py 16384 30 physics_only,full,percall_full,percall_pooled,percall_render 96 gym-pusht

One process, one N, MJX-Warp (MJX_PUSHT_ENV_GRAPH_MODE picks the CUDA-graph mode). Variants:
`physics_only` (the env's mjx.Data, frame_skip mjx.steps at the action's ctrl, nothing else),
`plain` (the env's control step: physics, invariants, task score), `full` (plus the autoreset);
each in a `lax.scan` of STEPS steps, and `percall_*` the same step jitted once and called STEPS
times from Python. With PIXELS (an image size) the env renders in its step, and three more variants
split the pixel vector env's step: `percall_final` (the autoreset that also renders each ended
episode's last image, as the vector env's same-step mode did for `final_obs`: two renders a step),
`percall_pooled` (the same outputs from one render a step, the new episodes' first images taken from the
start pool: what the vector env's same-step mode runs since docs/notebook/samestep.md), `percall_render`
(the render alone, on the state's Data) and `gym_jax` / `gym_torch` (the gymnasium vector env, same-step
autoreset, jax or torch arrays out, zero actions). A fifth argument, `gym-pusht`, runs the drop-in's
scene (its view, its servos, target actions: the policy's output in metres) in place of the chapter's,
so the two scenes' physics and renders compare (`gym_*` stay PushT-v0's).
Figures are N x STEPS / seconds of the second call.
Results: notebook changes 13 and 22.
"""
import json
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
from mujoco import mjx

from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.wrappers import AutoReset

n, steps = int(sys.argv[1]), int(sys.argv[2])
variants = sys.argv[3].split(",")
pixels = int(sys.argv[4]) if len(sys.argv) > 4 else 0
variant = sys.argv[5] if len(sys.argv) > 5 else "chapter"  # gym-pusht: the drop-in's scene, target actions
if variant == "gym-pusht":
    from mjx_pusht.model.scene import SceneSpec

    env = PushTEnv(backend="mjx-warp", pixels=pixels, scene=SceneSpec(variant="gym-pusht"), action_type="target")
else:
    env = PushTEnv(backend="mjx-warp", pixels=pixels)
ar = AutoReset(env, mode="same_step")
ar_final = AutoReset(env, mode="same_step", final_pixels=True, image_pool=False)
ar_pooled = AutoReset(env, mode="same_step", final_pixels=True)
s = ar.reset(np.arange(n))
s_final = ar_final.reset(np.arange(n)) if "percall_final" in variants else None
s_pooled = ar_pooled.reset(np.arange(n)) if "percall_pooled" in variants else None
W = jax.random.normal(jax.random.PRNGKey(0), (5, 2)) * 0.5
d0 = env.template(n)
out = {"n": n, "steps": steps, "pixels": pixels, "variant": variant, "device": str(jax.devices()[0])}

def plain(s):
    a = jnp.tanh(s.obs["state"] @ W)
    st = jax.vmap(env.advance_one)(s._replace(info=None), a)
    return st._replace(info=s.info)

def full(s):
    return ar._step_batch(d0, s, jnp.tanh(s.obs["state"] @ W))

def final(s):
    return ar_final._step_batch(d0, s, jnp.tanh(s.obs["state"] @ W))

def render(s):  # the image of each world's current Data, nothing else
    return s._replace(obs={**s.obs, "pixels": jax.vmap(env._renderer)(s.data)})

def physics_only(s):  # the env's data, its frame_skip mjx.steps at the action's ctrl, nothing else
    a = jnp.tanh(s.obs["state"] @ W)
    def one(d, u):
        return jax.lax.scan(lambda d, _: (mjx.step(env._mx, d.replace(ctrl=u)), None), d, None, env.episode.frame_skip)[0]
    return s._replace(data=jax.vmap(one)(s.data, a))

def scan_of(fn):
    @jax.jit
    def run(s):
        return jax.lax.scan(lambda s, _: (fn(s), None), s, None, steps)[0]
    return run

def timed(name, run, s):
    try:
        t0 = time.perf_counter(); s1 = jax.block_until_ready(run(s)); c = time.perf_counter() - t0
        t0 = time.perf_counter(); jax.block_until_ready(run(s1)); dt = time.perf_counter() - t0
        out[name] = {"steps_per_s": n * steps / dt, "ms_per_step": 1000 * dt / steps, "first_call_s": c,
                     "compiles": getattr(run, "_cache_size", lambda: None)()}  # 1: the timed call compiled nothing
    except Exception as e:  # noqa: BLE001 - a failed variant is recorded, the rest still run
        out[name] = {"error": f"{type(e).__name__}: {str(e).splitlines()[0][:200]}"}
    print(json.dumps({name: out[name]}), flush=True)

def gym(array_type):
    import gymnasium as gym

    import mjx_pusht  # noqa: F401  (registers the envs)

    envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=n, backend="mjx-warp", array_type=array_type,
                        obs_type="pixels_agent_pos" if pixels else "state", autoreset_mode="same_step")
    envs.reset(seed=0)
    zero = np.zeros((n, 2), np.float32)
    if array_type == "torch":
        import torch

        zero = torch.zeros((n, 2), device="cuda")

    def run(_):
        for _ in range(steps):
            envs.step(zero)
        return envs._state.reward
    return run

for v in variants:
    if v.startswith("gym_"):
        timed(v, gym(v[4:]), s)
    elif v == "percall_pooled":  # AutoReset.step: its jitted step, the pool's images handed in beside the state
        def run(s):
            for _ in range(steps):
                s = ar_pooled.step(s, jnp.tanh(s.obs["state"] @ W))
            return s
        timed(v, run, s_pooled)
    elif v.startswith("percall_"):
        fn = {"percall_plain": plain, "percall_full": full, "percall_final": final, "percall_render": render}[v]
        j = jax.jit(fn)
        def run(s, j=j):
            for _ in range(steps):
                s = j(s)
            return s
        timed(v, run, s_final if v == "percall_final" else s)
    else:
        timed(v, scan_of({"plain": plain, "full": full, "physics_only": physics_only}[v]), s)
print("RESULT " + json.dumps(out), flush=True)
