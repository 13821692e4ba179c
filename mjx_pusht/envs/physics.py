"""Physics drawn per episode in the functional env (`PushTEnv(randomize=...)`, model/randomize.py).

Each episode's (k,) scale factors ride in its state (`State.physics`), drawn on the host from its seed at a
reset, as the sweep's and eval's rows draw them, so a seed has the same physics everywhere. On MJX a world's
model is the scene's with its drawn fields set inside the step (the grid's `WorldFields`: one compiled step
for every draw); on MuJoCo C each world steps its own MjModel.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht import validate
from mjx_pusht.model.params import CURRENT
from mjx_pusht.model.randomize import factors, row_models, values


def draw(env, seeds) -> np.ndarray | None:
    """(N, k) the factors the episodes of `seeds` draw; None without `randomize` (the state's physics then)."""
    r = env.scenario.randomize
    return factors(r, validate.seed_array(seeds)) if r else None


def cpu_models(env, f: np.ndarray):
    """MuJoCo C's model per world (each row's drawn physics), or the env's one model."""
    return row_models(env.model, env.scenario.randomize, f) if env.scenario.randomize else env.model


def world_model(env, physics):
    """One MJX world's model: the scene's with its drawn fields set (traced; under vmap a field per world)."""
    return env._mx if physics is None else env.runner.models.fields.world(env._mx, physics)


def drawn_values(env, state) -> dict:
    """Each episode's drawn physics as the parameters' own values (kg, gains), by name; {} without `randomize`."""
    f = state.physics
    return {} if f is None else values(env.model, env.scenario.randomize, np.asarray(f, np.float64))


def info(env, physics, xp=np) -> dict:
    """What every env built on this one adds to its `info` (gymnasium single and vector, the drop-in, Brax):
    {"physics": {name: value}}, the episodes' drawn values in the parameters' own units, the same numbers as
    `drawn_values` and eval's param_ columns (factor x the scene's own), in `xp` (traced inside a jitted view);
    {} without `randomize`, so an env asked for nothing gives the info it always gave."""
    if physics is None:
        return {}
    own = [CURRENT[name](env.model) for name, _ in env.scenario.randomize]
    f = physics if xp is not np else np.asarray(physics, np.float64)
    return {"physics": {name: f[..., j] * own[j] for j, (name, _) in enumerate(env.scenario.randomize)}}
