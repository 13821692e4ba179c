"""Judging a PPO policy: Brax's params as a `policy:PATH` checkpoint, the held-out and validation episodes
that judge it, and the checks on its weights.

The policy Brax learns (an MLP on Brax's running observation normalisation, tanh-squashed
Gaussian) is saved as a `policy:PATH` checkpoint (policy.py): the normaliser's mean and std, the
layers, and which action it acts with (ppo_policy.py): by default a draw from the Gaussian keyed
by seed and step, the policy PPO trains; or its mean, tanh(loc), Brax's own `make_policy(...,
deterministic=True)` (tests check both against Brax). The mean action is not what PPO optimises:
it stalls where the trained policy's noise carries it on, and its held-out rate swung 5-93%
between judgements while PPO learned (docs/notebook/training.md), so every judgement measures
both, and `--keep best` chooses by validation seeds, never the held-out ones.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht.train.policy import PPO_ACTS


def to_checkpoint(params, obs_type: str, act: str = "mean") -> tuple[dict, dict]:
    """Brax's (normaliser, policy, value) params -> (layers, meta) of a policy.py checkpoint."""
    normalizer, policy = params[0], params[1]
    layers = policy["params"]
    names = sorted((k for k in layers if k.startswith("hidden_")), key=lambda k: int(k.split("_")[1]))
    dense = {f"Dense_{i}": {"kernel": np.asarray(layers[k]["kernel"]), "bias": np.asarray(layers[k]["bias"])}
             for i, k in enumerate(names)}
    meta = {"method": "ppo", "obs_type": obs_type, "activation": "silu", "act": act,
            "in_mean": [float(v) for v in np.asarray(normalizer.mean)],
            "in_std": [float(v) for v in np.asarray(normalizer.std)]}
    return dense, meta


def make_judge(env, cfg):
    """A jitted judge: checkpoint layers and meta -> {"mean", "sample"} x {"held_out", "validation"} per-episode
    success and final coverage, and the count of episodes whose observation went non-finite. Both actions run in one
    batch (held-out and validation seeds, each twice), so judging the action not saved costs little on a GPU."""
    import jax
    import jax.numpy as jnp

    from mjx_pusht.train.ppo_policy import ppo_action, ppo_input

    held, val = cfg.held_out_seeds(), cfg.validation_seeds()
    seeds = np.concatenate([held, val, held, val])
    sample = jnp.asarray(np.repeat([0.0, 1.0], len(held) + len(val)), jnp.float32)
    s0 = env.reset(seeds)

    def episode(dense, mean, std, s, noise):
        meta = {"in_mean": mean, "in_std": std, "activation": "silu"}

        def body(s, _):
            # what the checkpoint's controller reads (the yaw in the task's window), so the judge is eval's episodes
            obs = ppo_input({"obs_type": cfg.obs_type, "config": {"task": cfg.task}}, s.obs)
            action = cfg.the_task.from_velocity(ppo_action(dense, meta, obs, s.key, s.step, noise), s.obs)
            return env.advance_one(s, action), None

        s, _ = jax.lax.scan(body, s, None, cfg.max_steps)
        return s.metrics["success"], s.metrics["coverage"], jnp.isfinite(s.obs[cfg.obs_type]).all()

    run = jax.jit(jax.vmap(episode, in_axes=(None, None, None, 0, 0)))

    def judge(dense, meta):
        success, cov, finite = (np.asarray(v) for v in run(dense, jnp.asarray(meta["in_mean"], jnp.float32),
                                                             jnp.asarray(meta["in_std"], jnp.float32), s0, sample))
        n, out = len(held) + len(val), {"non_finite": int((~finite).sum())}
        for i, act in enumerate(PPO_ACTS):
            parts = {"held_out": slice(i * n, i * n + len(held)), "validation": slice(i * n + len(held), (i + 1) * n)}
            for name, part in parts.items():
                out[act, name] = (success[part].astype(bool), cov[part].astype(float))
        return out

    return judge


def std_change(before, after) -> float | None:
    """The largest relative change of the observation normaliser's std over the inputs since the last judgement:
    one far-out training observation moves it at once (Brax's running statistics), and every input the policy
    sees with it (a suspect for a collapse, recorded per judgement as `norm_std_change`)."""
    if before is None:
        return None
    return float(np.max(np.abs(np.asarray(after) / np.asarray(before) - 1.0)))


def finite(tree) -> bool:
    import jax

    return all(bool(np.isfinite(np.asarray(x)).all()) for x in jax.tree.leaves(tree))



def weights_digest(params, obs_type: str) -> str:
    """16 hex digits of SHA-256 over the policy's layers as float32 (the checkpoint's `Dense_i` kernels and biases,
    in the order jax.tree.leaves gives a loaded checkpoint's): equal digests, equal weights."""
    import hashlib

    import jax

    dense, _ = to_checkpoint(params, obs_type)
    return hashlib.sha256(b"".join(np.asarray(a, np.float32).tobytes() for a in jax.tree.leaves(dense))).hexdigest()[:16]
