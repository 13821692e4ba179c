"""Partial reset: some rows of a batch start new episodes, the rest run on (a vector env's autoreset).

On the cpu backend this is NumPy only (no JAX: a CPU env may be forked); on MJX one `jnp.where` per array.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht import validate
from mjx_pusht.errors import ConfigError
from mjx_pusht.task.reset import start_poses


def reset_where(env, state, mask, seeds=None, starts=None):
    """`state` with the rows where `mask` holds started afresh (from `seeds`' start poses, or `starts`),
    every other row untouched."""
    from mjx_pusht.envs.state import check_state

    check_state(state, env.backend, env, what="reset_where")  # not a State: was an AttributeError
    mask = validate.mask(mask, len(state.step), "mask")
    rows = np.flatnonzero(mask)
    if not len(rows):
        return state
    if state.info is not None:  # a wrapper's arrays are not per world: they pass through
        return env.reset_where(state._replace(info=None), mask, seeds, starts)._replace(info=state.info)
    if starts is None:
        if seeds is None:
            raise ConfigError("reset_where needs seeds (one per reset row) or starts")
        seeds = validate.seed_array(seeds)
        starts = start_poses(seeds, reset=env.reset_kind)
        starts_seeds, drawn = seeds, True
    else:
        starts = np.atleast_2d(np.asarray(starts, np.float64))
        starts_seeds = np.zeros(len(starts), np.int64) if seeds is None else validate.seed_array(seeds)
        drawn = False
    if len(starts_seeds) != len(starts):
        raise ConfigError(f"seeds: {len(starts_seeds)} seeds for {len(starts)} start states")
    if not drawn:  # a given start: the same checks as reset_to's, once, here
        starts = env.given_starts(starts)
    if len(starts) != len(rows):
        what = "starts" if drawn is False else "seeds"
        raise ConfigError(f"{what}: {len(starts)} for the {len(rows)} rows the mask resets")
    if env.backend == "cpu":
        fresh = env.reset_to(starts, starts_seeds, drawn=True)

        def put(old, new):
            out = np.array(old, copy=True)
            out[rows] = new
            return out

        merged = _tree_map(put, state._replace(data=None), fresh._replace(data=None))
        return merged._replace(data=state.data.splice(rows, fresh.data, inplace=not env.keep_states))
    import jax
    import jax.numpy as jnp

    n = len(state.step)
    full = np.zeros((n, starts.shape[1]))
    full[rows] = starts
    full_seeds = np.zeros(n, np.int64)
    full_seeds[rows] = starts_seeds
    fresh = env.reset_to(full, full_seeds, drawn=True)  # the given rows were checked above
    m = jnp.asarray(mask)

    def pick(old, new):
        if new.ndim == 0 or new.shape[0] != n:
            return old  # not a per-world array (MJX-Warp's shared contact buffers, recomputed every step)
        c = m.reshape(m.shape + (1,) * (new.ndim - 1))
        return jnp.where(c, new, old)

    return jax.tree.map(pick, state, fresh)


def _tree_map(fn, a, b):
    """`fn` over the leaves of two like NamedTuples of dicts of NumPy arrays."""
    if isinstance(a, dict):
        return {k: _tree_map(fn, a[k], b[k]) for k in a}
    if isinstance(a, tuple):
        return type(a)(*(_tree_map(fn, x, y) for x, y in zip(a, b)))
    return None if a is None else fn(a, b)
