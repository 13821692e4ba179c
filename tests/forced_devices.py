"""Run by tests/test_devices.py in a process of its own, with XLA_FLAGS forcing 2 CPU devices (JAX cannot change its
device count once imported): fits the same data, or rolls out the same seeds, on 1 and on 2 of them and prints what
each gave, as JSON, for the test to compare.

    python tests/forced_devices.py fit|rollout|pixels|both|all[:BACKEND]
"""

from __future__ import annotations

import json
import sys

import numpy as np


def fit() -> dict:
    """One Learner per device count, the same ring and seed: weights, optimiser state and loss after a fit."""
    import jax

    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.devices import Spread
    from mjx_pusht.train.learner import Learner

    cfg = DaggerConfig(hidden=(32, 32), batch=64, fit_steps=20, max_samples=4096, learning_rate=3e-3)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(1000, cfg.sample_width)).astype(np.float32)
    y = np.concatenate([rng.uniform(-0.2, 0.2, (1000, 2)), rng.integers(0, 4, (1000, 1))], 1).astype(np.float32)
    out = {"start": [np.asarray(a).ravel().tolist() for a in jax.tree.leaves(Learner(cfg).params)]}
    for n in (1, 2):
        learner = Learner(cfg, spread=Spread(jax.devices()[:n]))
        learner.add(x, y, keep=True)
        loss = learner.fit(0)
        out[n] = {"loss": loss, "devices": len(learner.params["Dense_0"]["kernel"].sharding.device_set),
                  "params": [np.asarray(a).ravel().tolist() for a in jax.tree.leaves(learner.params)]}
    return out


def rollout(backend: str) -> dict:
    """One rollout of 8 seeds (6 learned from, 2 judged) by an untrained student mixed with the expert, on 1 and 2
    devices: every episode's outcome and the compacted samples and labels."""
    import jax

    from mjx_pusht.train.dagger import DaggerConfig, Rollouts
    from mjx_pusht.train.devices import Spread
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.run import _unit, dagger_env

    cfg = DaggerConfig(envs=6, eval_envs=2, max_steps=12, hidden=(32, 32), batch=64, max_samples=4096, reset="chapter")
    env, params = dagger_env(cfg, backend), Learner(cfg).params
    out = {}
    for n in (1, 2):
        x, y, k, outcome = Rollouts(env, cfg, Spread(jax.devices()[:n])).padded(params, _unit(cfg), np.arange(8), 0.5,
                                                                                  0, 6)
        out[n] = {"x": np.asarray(x[:k]).tolist(), "y": np.asarray(y[:k]).tolist(),
                  "devices": len(x.sharding.device_set) if hasattr(x, "sharding") else 1,
                  **{key: np.asarray(v).tolist() for key, v in outcome.items()}}
    return out


def pixels(backend: str) -> dict:
    """A pixel student on 1 and 2 devices: a rollout of 4 seeds (the images drawn in it by the raster renderer on
    each device), then a fit of its samples (each device rendering its share of every minibatch again)."""
    import jax

    from mjx_pusht.train.dagger import DaggerConfig, Rollouts
    from mjx_pusht.train.devices import Spread
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.run import _unit, dagger_env

    cfg = DaggerConfig(obs_type="pixels_agent_pos", envs=2, eval_envs=2, max_steps=6, hidden=(16,), batch=8,
                       image_batch=4, fit_steps=3, image_steps=3, max_samples=512, reset="chapter")
    env, out = dagger_env(cfg, backend), {}
    for n in (1, 2):
        spread = Spread(jax.devices()[:n])
        learner = Learner(cfg, env.images(cfg.image_batch // n), spread)
        x, y, k, outcome = Rollouts(env, cfg, spread).padded(learner.params, _unit(cfg), np.arange(4), 0.5, 0, 2)
        learner.add(x, y, keep=True, n=k)
        loss = learner.fit(0)
        out[n] = {"x": np.asarray(x[:k]).tolist(), "coverage": np.asarray(outcome["coverage"]).tolist(),
                  "loss": loss, "pose_error_mm": learner.pose_error_mm,
                  "params": [np.asarray(a).ravel().tolist() for a in jax.tree.leaves(learner.params)]}
    return out


if __name__ == "__main__":
    what, _, backend = sys.argv[1].partition(":")
    jobs = {"fit": fit, "rollout": lambda: rollout(backend or "mjx-jax"), "pixels": lambda: pixels(backend or "mjx-jax")}
    print(json.dumps({k: f() for k, f in jobs.items() if what in (k, "all") or what == "both" and k != "pixels"}))
