"""Which of a scene's drawn geoms the MJX-Warp ray tracer pays for: the render alone, at N worlds, with the whole
view and with each group of geoms left out of it (moved to a geom group the renderer does not draw).

    python benchmarks/render_geoms.py N [chapter|gym-pusht] [REPEATS]

One process, one N, 96 x 96 images of the env's own reset states. Prints one JSON line a variant and a RESULT line.
Results: docs/notebook/lead.md (the drop-in's pixel step at 65,536 envs).
"""
import copy
import json
import sys
import time

import jax
import numpy as np

from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.render.pixels import WarpRenderer

n = int(sys.argv[1])
variant = sys.argv[2] if len(sys.argv) > 2 else "gym-pusht"
repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 10
env = PushTEnv(backend="mjx-warp", scene=SceneSpec(variant=variant), action_type="target") if variant == "gym-pusht" else PushTEnv(backend="mjx-warp")
data = env.reset(np.arange(n)).data
model = env.model
names = [model.geom(i).name for i in range(model.ngeom)]
drawn = [nm for i, nm in enumerate(names) if model.geom_group[i] == 0]
groups = {"all": []}
for key in ("wall", "tee_bar_edge,tee_stem_edge", "target", "pusher", "table"):
    hit = [nm for nm in drawn if any(nm.startswith(k) for k in key.split(","))]
    if hit:
        groups["no_" + key.split(",")[0].split("_")[0] + ("_edges" if "edge" in key else "")] = hit
out = {"n": n, "variant": variant, "device": str(jax.devices()[0]), "drawn": drawn}
print(json.dumps(out), flush=True)
for name, hidden in groups.items():
    m = copy.deepcopy(model)
    for nm in hidden:
        m.geom_group[m.geom(nm).id] = 3
    r = WarpRenderer(m, n)
    f = jax.jit(jax.vmap(r))
    jax.block_until_ready(f(data))
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(f(data))
        times.append(time.perf_counter() - t0)
    row = {"hidden": hidden, "ms_median": 1000 * float(np.median(times)), "ms_min": 1000 * min(times)}
    out[name] = row
    print(json.dumps({name: row}), flush=True)
    del r, f
print("RESULT", json.dumps(out), flush=True)
