"""The three renderers of the top view, timed on the same states: images/s, and how many pixels each pair differs in.

- raster: render/raster.py's `state_images` (plain JAX ops: MJX's kinematics, then each pixel's highest geom),
  jitted over the batch, on JAX's default device;
- warp: MJX-Warp's ray tracer (render/pixels.py `WarpRenderer` on an mjx-warp env's Data: the same states in, one jitted
  call over the batch), on Warp's CUDA device, or its CPU device where there is no GPU;
- cpu: MuJoCo C's OpenGL renderer (`CpuRenderer`) over the same qpos, one image after another (needs GL: EGL or
  OSMesa; a GPU machine without it leaves it out with --renderers raster,warp).

Each figure is the rate of one call over the batch (block_until_ready), after a warm-up call, for at least a second
and 3 calls (benchmarks/render.py's `_rate`). The states are the task's starts (its reset) for seeds 0..N-1, those
of seeds 0..4095 repeated beyond 4,096 (a renderer's cost does not depend on where the T lies).

    python -m benchmarks.raster --batches 512 --json benchmarks/results/cpu-raster.json          # this machine
    python -m benchmarks.raster --renderers raster,warp --batches 512,4096,65536 --json OUT.json  # a GPU
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.render import _rate

RENDERERS = ("raster", "warp", "cpu")


def _warp_images(env, n: int):
    """MJX-Warp's ray tracer on (n, 5) states, as the env renders a step's Data (pixels.state_images is MuJoCo C's
    since training draws with the raster: with it, this benchmark asked a GPU machine for OpenGL and failed)."""
    import jax

    from mjx_pusht.render.pixels import WarpRenderer

    q0, renderer, d0 = np.asarray(env.model.qpos0, np.float64), WarpRenderer(env.model, n, env.pixels), env.template(n)
    return lambda states: jax.vmap(lambda q: renderer(d0.replace(qpos=q)))(
        env.layout.qpos_of_state(q0, states.astype(env.runner.dtype)))


def measure(task: str, n: int, size: int, renderers: list[str]) -> dict:
    import jax
    import jax.numpy as jnp

    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.render import pixels, raster

    env = PushTEnv.for_task(task, pixels=size)  # on the cpu backend: the states and the model
    # the task's starts, settled on MuJoCo C (one thread: ~1.3 ms a seed here), repeated past 4,096
    starts = PushTEnv.for_task(task).reset(np.arange(min(n, 4096))).obs["state"]
    states = np.resize(np.asarray(starts, np.float32), (n, 5))
    qpos = env.layout.qpos_of_state(np.asarray(env.model.qpos0), states.astype(np.float64))
    fns = {}
    if "raster" in renderers:
        fn = jax.jit(raster.state_images(env))
        fns["raster"] = lambda: jax.block_until_ready(fn(jnp.asarray(states)))
    if "warp" in renderers:
        wfn = jax.jit(_warp_images(PushTEnv.for_task(task, backend="mjx-warp", pixels=size), n))
        fns["warp"] = lambda: jax.block_until_ready(wfn(jnp.asarray(states)))
    if "cpu" in renderers:
        cpu = pixels.CpuRenderer(env.model, size)
        fns["cpu"] = lambda: cpu(qpos)
    row = {"task": task, "batch": n, "size": size}
    images = {}
    for name, f in fns.items():
        t0 = time.perf_counter()
        images[name] = np.asarray(f())
        row[f"{name}_first_call_seconds"] = round(time.perf_counter() - t0, 3)
        row[name] = _rate(f, n)
        print(f"{task:9s} N={n:6d} {name:6s} {row[name]['per_second']:>12,.0f} images/s", flush=True)
    names = list(images)
    row["differing_pixel_fraction"] = {f"{a}-{b}": float((images[a] != images[b]).any(-1).mean())
                                       for i, a in enumerate(names) for b in names[i + 1:]}
    print(f"{task:9s} N={n:6d} differing pixels: {row['differing_pixel_fraction']}", flush=True)
    return row


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tasks", default="chapter,gym-pusht")
    p.add_argument("--batches", default="512", help="images a call, comma-separated (default 512: the learner's)")
    p.add_argument("--size", type=int, default=96)
    p.add_argument("--renderers", default=",".join(RENDERERS), help=f"some of {', '.join(RENDERERS)}")
    p.add_argument("--json", type=Path, required=True, help="the JSON file to write")
    args = p.parse_args(argv)
    renderers = args.renderers.split(",")
    if set(renderers) - set(RENDERERS):
        p.error(f"--renderers: choose from {', '.join(RENDERERS)}")
    import jax

    from mjx_pusht.backends.base import versions
    from mjx_pusht.io.banner import tier

    rows = [measure(t, int(n), args.size, renderers) for t in args.tasks.split(",") for n in args.batches.split(",")]
    result = {"what": "images/s of the raster, MJX-Warp and MuJoCo C renderers of the same states",
              "host": tier(), "jax_device": str(jax.devices()[0]), "versions": versions(),
              "date": time.strftime("%Y-%m-%d"), "rows": rows}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
