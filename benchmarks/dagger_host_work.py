"""DAgger's work between its device programs (notebook lead7), measured apart from a run:

- `ring`: a rollout's samples compacted (`Rollouts`' `_compact`, or before it the eager compaction it replaced,
  `--eager`) and added to the ring (`Learner.add`), for batches whose counts differ as episodes end at different
  steps: seconds and XLA programs compiled per iteration.
- `checkpoint`: the resume checkpoint of a full ring (`resume.checkpoint`), how long its writer runs and how fast a
  loop of small jitted steps on the main thread goes meanwhile, against alone (training needs the GIL between its
  device calls: a writer that holds it stops training).

    python -m benchmarks.dagger_host_work --envs 4096 --samples 2000000 --ring-samples 32000000

Figures go to stdout and, with --json, to a file.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def ring(envs: int, samples: int, iterations: int, eager: bool = False) -> list[dict]:
    """Each iteration's samples, seconds and XLA programs compiled (JAX's compile log, counted)."""
    import jax

    compiled = []

    class Seen(logging.Handler):
        def emit(self, record):
            if record.getMessage().startswith("Finished XLA compilation"):
                compiled.append(record.getMessage())

    log, seen = logging.getLogger("jax._src.dispatch"), Seen()
    log.addHandler(seen)
    log.propagate = False  # counted, not printed
    try:
        with jax.log_compiles(True):
            return _ring(envs, samples, iterations, eager, compiled)
    finally:
        log.removeHandler(seen)
        log.propagate = True


def _ring(envs, samples, iterations, eager, compiled) -> list[dict]:
    import jax
    import jax.numpy as jnp

    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.learner import Learner

    cfg = DaggerConfig(hidden=(32, 32), max_samples=samples, envs=envs)
    learner = Learner(cfg)
    if not eager:
        from mjx_pusht.train.dagger import _compact

        compact = jax.jit(lambda *a: _compact(*a, learn=envs))
    steps, worlds, width = cfg.max_steps, 2 * envs, cfg.sample_width  # training rows and as many held out
    rng, rows = np.random.default_rng(0), []
    for i in range(iterations):
        ends = rng.integers(20, steps, worlds)
        live = jnp.asarray(np.arange(steps)[:, None] < ends[None, :])
        x = jnp.asarray(rng.normal(size=(steps, worlds, width)).astype(np.float32))
        y = jnp.zeros((steps, worlds, 3), jnp.float32)
        jax.block_until_ready((x, y, live))
        before, t = len(compiled), time.perf_counter()
        if eager:  # as Rollouts._mjx compacted before notebook lead7: to the count, a new shape each time
            xs, ys, ls = (jnp.swapaxes(a[:, :envs], 0, 1) for a in (x, y, live))
            keep = jnp.nonzero(ls.reshape(-1))[0]
            xs, ys, n = xs.reshape(-1, width)[keep], ys.reshape(-1, 3)[keep], len(keep)
            learner.add(xs, ys, keep=i == 0)  # all of them samples (as Learner.add took them before, too)
        else:
            xs, ys, n = compact(x, y, live)
            n = int(n)
            learner.add(xs, ys, keep=i == 0, n=n)
        jax.block_until_ready(learner.x)
        rows.append({"iteration": i, "samples": n, "seconds": time.perf_counter() - t,
                     "compiled": len(compiled) - before})
        print(f"ring {'eager' if eager else 'one program'}: iteration {i}: {n} samples, "
              f"{rows[-1]['seconds']:.3f} s, {rows[-1]['compiled']} programs compiled", flush=True)
    return rows


def checkpoint(ring_samples: int) -> dict:
    import jax
    import jax.numpy as jnp

    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.resume import checkpoint as write

    cfg = DaggerConfig(hidden=(1024, 1024, 1024), max_samples=ring_samples)
    learner = Learner(cfg)
    learner.norm, learner.filled = (np.zeros(cfg.sample_width), np.ones(cfg.sample_width)), ring_samples
    step = jax.jit(lambda a: (a @ a.T).sum())
    a = jnp.ones((256, 256))
    step(a).block_until_ready()

    def rate(seconds: float) -> float:
        n, t = 0, time.perf_counter()
        while time.perf_counter() - t < seconds:
            step(a).block_until_ready()
            n += 1
        return n / seconds

    alone = rate(2.0)
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        writer = write(Path(tmp) / "resume.msgpack", cfg, learner, 0, 0, [])
        handed = time.perf_counter() - t
        n, t = 0, time.perf_counter()
        while writer.is_alive():
            step(a).block_until_ready()
            n += 1
        writing = time.perf_counter() - t
        writer.join()
    out = {"ring_bytes": int(learner.x.nbytes + learner.y.nbytes), "main_thread_seconds": handed,
           "writer_seconds": writing, "steps_per_s_while_writing": n / writing, "steps_per_s_alone": alone}
    print(f"checkpoint of {out['ring_bytes'] / 1e9:.2f} GB: {handed:.2f} s on the main thread, the writer "
          f"{writing:.2f} s after it; small jitted steps meanwhile {out['steps_per_s_while_writing']:.0f}/s, "
          f"alone {alone:.0f}/s", flush=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--envs", type=int, default=4096, help="training episodes an iteration (as many held out)")
    p.add_argument("--samples", type=int, default=2_000_000, help="the ring of the `ring` measurement")
    p.add_argument("--iterations", type=int, default=8)
    p.add_argument("--ring-samples", type=int, default=32_000_000, help="the full ring `checkpoint` writes")
    p.add_argument("--eager", action="store_true", help="the compaction as Rollouts had it before notebook lead7, and Learner.add without a count: "
                   "what ran before when this script is run at commit c63b087 (here Learner.add compiles its ring write "
                   "per count instead)")
    p.add_argument("--only", choices=("ring", "checkpoint"))
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    result = {"device": None, "ring": None, "checkpoint": None, "argv": sys.argv[1:]}
    import jax

    result["device"] = str(jax.devices()[0])
    if args.only != "checkpoint":
        result["ring"] = ring(args.envs, args.samples, args.iterations, args.eager)
    if args.only != "ring":
        result["checkpoint"] = checkpoint(args.ring_samples)
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
