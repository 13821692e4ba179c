"""Pixel observations, measured: the renderer alone, the physics alone and the pixel environment, in one run.

    python -m benchmarks.render --backend mjx-warp --batches 1024,4096,16384,65536   # on a GPU
    python -m benchmarks.render --backend cpu                                        # this machine
    python -m benchmarks.render --compare OUT/pixels-h100.npz --into results/h100-render.json

On MJX-Warp every figure is one jitted call over N worlds, timed after a warm-up call until the
result is on the device (block_until_ready): `physics` is the control step without images (10
physics steps), `render` is MJX-Warp's ray tracer alone on those worlds (uint8 RGB out), `pixel_env`
is the control step with the image rendered inside the same program, `pixel_env_images_to_host` the
same with its images copied to a NumPy array each call, and `vector_env` is
gymnasium's make_vec with pixels, images copied to the host as NumPy. `--save-pixels` keeps the
images of 64 known states so the CPU renderer's images of the same states can be compared here
(`--compare`), since the GPU machine has no OpenGL.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import numpy as np

SIZE = 96


def _rate(fn, n_items: int, min_seconds: float = 1.0, min_reps: int = 3) -> dict:
    """Items per second of fn() (which must block until done), after one warm-up call."""
    fn()
    reps, t0 = 0, time.perf_counter()
    while reps < min_reps or time.perf_counter() - t0 < min_seconds:
        fn()
        reps += 1
    dt = (time.perf_counter() - t0) / reps
    return {"seconds_per_call": dt, "per_second": n_items / dt, "reps": reps}


def measure_mjx(batches: list[int], save_pixels: Path | None) -> dict:
    import jax

    from mjx_pusht.envs.functional import PushTEnv

    rows = []
    plain = PushTEnv(backend="mjx-warp")
    pixel = PushTEnv(backend="mjx-warp", pixels=SIZE)
    for n in batches:
        seeds = np.arange(n)
        act = np.tile([[0.3, 0.4]], (n, 1)).astype(np.float32)
        row = {"batch": n}
        s = plain.reset(seeds)
        row["physics"] = _rate(lambda: jax.block_until_ready(plain.step(s, act)), n)
        ps = pixel.reset(seeds)
        pixel._batch_fns(n)
        render = jax.jit(jax.vmap(pixel._renderers[n]))
        row["render"] = _rate(lambda: jax.block_until_ready(render(ps.data)), n)
        row["pixel_env"] = _rate(lambda: jax.block_until_ready(pixel.step(ps, act)), n)
        # what a host-side consumer (gymnasium's vector env) adds: each step's images copied to NumPy
        row["pixel_env_images_to_host"] = _rate(lambda: np.asarray(pixel.step(ps, act).obs["pixels"]), n)
        out = pixel.step(ps, act)
        assert out.obs["pixels"].shape == (n, SIZE, SIZE, 3) and out.obs["pixels"].dtype == np.uint8
        for k in ("physics", "render", "pixel_env", "pixel_env_images_to_host"):
            print(f"N={n:6d} {k:10s} {row[k]['per_second']:>12,.0f} /s", flush=True)
        rows.append(row)
    if save_pixels is not None:
        n = 64
        e = PushTEnv(backend="mjx-warp", pixels=SIZE)
        st = e.reset(np.arange(n))
        for _ in range(5):
            st = e.step(st, np.tile([[0.3, 0.4]], (n, 1)))
        np.savez_compressed(save_pixels, qpos=np.asarray(st.data.qpos), pixels=np.asarray(st.obs["pixels"]))
    return {"rows": rows}


def measure_vector_env(backend: str, n: int, obs_type: str, steps: int = 20) -> dict:
    import gymnasium as gym

    import mjx_pusht  # noqa: F401

    envs = gym.make_vec("mjx_pusht/PushT-v0", num_envs=n, backend=backend, obs_type=obs_type)
    envs.reset(seed=0)
    act = np.tile([[0.3, 0.4]], (n, 1))
    envs.step(act)  # compile
    t0 = time.perf_counter()
    for _ in range(steps):
        obs, *_ = envs.step(act)
    dt = time.perf_counter() - t0
    row = {"backend": backend, "num_envs": n, "obs_type": obs_type, "control_steps_per_second": n * steps / dt}
    row["step_seconds"] = dt / steps
    envs.close()
    return row


def measure_cpu() -> dict:
    import gymnasium as gym

    import mjx_pusht  # noqa: F401
    from mjx_pusht.render.pixels import CpuRenderer
    from mjx_pusht.model.layout import QposLayout
    from mjx_pusht.model.scene import SceneSpec, build_model
    from mjx_pusht.task.reset import start_poses

    model = build_model(SceneSpec())
    layout = QposLayout.of(model)
    qpos = layout.initial_qpos(model, start_poses(np.arange(512), reset="task"))
    r = CpuRenderer(model, SIZE)
    out = {"renderer_frames_per_second": _rate(lambda: r(qpos), len(qpos))["per_second"]}
    r.close()
    for obs_type in ("state", "pixels"):
        env = gym.make("mjx_pusht/PushT-v0", obs_type=obs_type)
        env.reset(seed=0)
        rng = np.random.default_rng(0)
        t0, steps = time.perf_counter(), 0
        while time.perf_counter() - t0 < 3.0:
            _, _, term, trunc, _ = env.step(rng.uniform(-1, 1, 2))
            steps += 1
            if term or trunc:
                env.reset()
        out[f"single_env_{obs_type}_steps_per_second"] = steps / (time.perf_counter() - t0)
        env.close()
    out["vector_env"] = [measure_vector_env("cpu", n, o) for n in (64, 512) for o in ("state", "pixels")]
    for k, v in out.items():
        print(k, v, flush=True)
    return out


def compare(npz: Path) -> dict:
    """The CPU renderer's images of the states the GPU rendered: how many pixels differ, and by how much."""
    from mjx_pusht.render.pixels import CpuRenderer
    from mjx_pusht.model.scene import SceneSpec, build_model

    data = np.load(npz)
    gpu = data["pixels"]
    r = CpuRenderer(build_model(SceneSpec()), gpu.shape[1])
    cpu = r(np.asarray(data["qpos"], np.float64))
    r.close()
    differ = (cpu != gpu).any(axis=-1)
    absdiff = np.abs(cpu.astype(int) - gpu.astype(int))
    return {"images": int(len(gpu)), "size": int(gpu.shape[1]), "pixels_differing": int(differ.sum()),
            "fraction_differing": float(differ.mean()), "max_abs_channel_diff": int(absdiff.max()),
            "mean_abs_channel_diff": float(absdiff.mean()),
            "what": "same qpos (the GPU's float32 state after 5 control steps from seeds 0..63) rendered by "
                    "MuJoCo C's OpenGL renderer on this machine and MJX-Warp's ray tracer on the GPU"}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--backend", default="cpu", choices=("cpu", "mjx-warp"))
    p.add_argument("--batches", default="1024,4096,16384,65536")
    p.add_argument("--tier", default=None, help="name of the result file (default: the backend)")
    p.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    p.add_argument("--save-pixels", type=Path, default=None)
    p.add_argument("--compare", type=Path, default=None, help="a --save-pixels file to compare with the CPU renderer")
    p.add_argument("--into", type=Path, default=None, help="with --compare: the result JSON to add the comparison to")
    p.add_argument("--vector-env", action="store_true", help="mjx-warp: only the gymnasium vector env, added to the file")
    args = p.parse_args()
    if args.compare:
        result = compare(args.compare)
        print(json.dumps(result, indent=2))
        if args.into:
            doc = json.loads(args.into.read_text())
            doc["gpu_vs_cpu_pixels"] = result
            args.into.write_text(json.dumps(doc, indent=2) + "\n")
        return
    from mjx_pusht.backends.base import versions

    doc = {"what": __doc__.split("\n\n")[1].strip(), "date": time.strftime("%Y-%m-%d"), "size": SIZE,
           "versions": versions(), "host": platform.node()}
    if args.backend == "cpu":
        import os

        doc["device"] = f"cpu ({len(os.sched_getaffinity(0))} cores)"
        doc["cpu"] = measure_cpu()
    else:
        import jax

        doc["device"] = f"{jax.devices()[0].platform}:{jax.devices()[0].device_kind}"
        path = args.out / f"{args.tier or args.backend}-render.json"
        if args.vector_env:
            # its own process: MJX-Warp's render contexts keep their buffers for the process's life
            doc = json.loads(path.read_text()) if path.exists() else doc
            doc["vector_env"] = [measure_vector_env("mjx-warp", n, "pixels") for n in (4096, 16384)]
            for v in doc["vector_env"]:
                print(v, flush=True)
        else:
            doc["mjx_warp"] = measure_mjx([int(b) for b in args.batches.split(",")], args.save_pixels)
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"{args.tier or args.backend}-render.json"
    path.write_text(json.dumps(doc, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
