"""A parameter grid's models on the device as one pytree: a row's model is gathered by index in one program.

Each combination is the CPU model edited and re-derived (`model.params.apply`), put on the
device; only the leaves that differ are stacked along a leading combo axis, so a sweep over
kv values is one compiled program. With no parameters swept there is one combination and
nothing is stacked.

Physics randomised per episode (model/randomize.py) rides on the same row: `row(leaves, combo, drawn)` is the
combination's model with each world's drawn fields set from its factors (`WorldFields`), traced inside the
program, so a batch of drawn worlds is still one compiled program and one model put on the device.
"""

from __future__ import annotations

import mujoco
import numpy as np


class ModelGrid:
    def __init__(self, model: mujoco.MjModel, grid: list[dict], *, impl: str, device, graph_mode: str | None = None,
                 randomize=()):
        import jax
        import jax.numpy as jnp
        from mujoco import mjx

        from mjx_pusht.model.params import apply, model_warnings
        from mjx_pusht.model.randomize import WorldFields

        models = [apply(model, g) for g in grid] if any(grid) else [model]
        # MuJoCo's verdict on each combination's model (a singular one, say): MJX raises no warnings itself
        self.warnings = np.array([model_warnings(m) for m in models], np.int32)
        kw = {}
        if impl == "warp":
            from mjx_pusht.backends.warp import finish_before_exit

            finish_before_exit(device)  # a CPU process would otherwise hang at exit on a step never read
        if graph_mode is not None:
            import warp as wp

            kw["graph_mode"] = wp.JaxCallableGraphMode[graph_mode]
        flat = [jax.tree.flatten(mjx.put_model(m, impl=impl, device=device, **kw)) for m in models]
        leaves, batched = [], []
        for column in zip(*(f[0] for f in flat)):
            same = all(np.array_equal(np.asarray(column[0]), np.asarray(c)) for c in column[1:])
            leaves.append(column[0] if same else jnp.stack([jnp.asarray(c) for c in column]))
            batched.append(not same)
        self.treedef, self.leaves, self.batched = flat[0][1], leaves, batched
        self.randomize, self.fields = randomize, WorldFields(model, randomize)
        self.n_drawn = len(randomize)
        if randomize:  # MuJoCo's verdict on the range's corners, where a singular model would be
            self.warnings = np.array([np.bitwise_or.reduce([model_warnings(m) for m in self._corners(model)])], np.int32)

    def leaves_on(self, device=None) -> list:
        """The model's array leaves, on `device` if given."""
        import jax

        return self.leaves if device is None else [jax.device_put(x, device) for x in self.leaves]

    def row(self, leaves, combo, drawn=None):
        """The mjx.Model of one row: stacked leaves indexed by the row's parameter combination, and its physics
        drawn per episode (`drawn`: its (k,) factors) set."""
        import jax

        mx = jax.tree.unflatten(self.treedef, [x[combo] if b else x for x, b in zip(leaves, self.batched)])
        return mx if drawn is None else self.fields.world(mx, drawn)

    def factors(self, seeds) -> np.ndarray:
        """(N, k) physics factors of the episodes of `seeds` (k = 0 when nothing is randomised)."""
        from mjx_pusht.model.randomize import factors

        return factors(self.randomize, seeds)

    def _corners(self, model):
        import itertools

        from mjx_pusht.model.randomize import row_models

        return row_models(model, self.randomize, np.array(list(itertools.product(*(r for _, r in self.randomize)))))

    def first(self):
        """The first combination's model (the only one when nothing is swept)."""
        return self.row(self.leaves, 0)
