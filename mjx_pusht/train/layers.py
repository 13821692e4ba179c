"""A checkpoint's Dense layers evaluated in the array namespace of their input (NumPy on MuJoCo C's side, JAX inside
MJX's scan): the activations, the normalise-then-Dense stack (`mlp`), and NumPy's fixed row blocks (`rowwise`).
policy.py (DAgger's students) and ppo_policy.py (Brax's PPO policies) both act through these."""

from __future__ import annotations

import numpy as np

from mjx_pusht.task.rules import array_namespace


def activation(name: str, x, xp):
    if name == "relu":
        return xp.maximum(x, 0.0)
    return x / (1.0 + xp.exp(-x))  # silu


# NumPy's matmul (BLAS) chooses its kernels, and so its order of summation, by the matrices' shapes, so a row's
# product moved in its last bits with the number of rows it came with; the contacts then amplify it, and a seed's
# MuJoCo C episode depended on which seeds shared its eval (the pixel policy of notebook change 28 ended seed
# 1000000002 at coverage 0.956 in a 9-seed eval and at 0.970 among 4,096). The Dense layers are evaluated in
# blocks of a fixed CPU_BLOCK rows, so a row's action is a function of its own observation alone. Measured on this
# repo's 2-core machine: 32-row blocks take a 1024 x 3 state network on 4,096 rows in the time of one product (0.24 s
# against 0.22). The image trunk is not blocked: its products are tall for one image already (47 x 47 rows), BLAS
# sums them alike whatever the batch (an image's map alone equals its map among 64, float32 and float64), and
# padding one image to 32 cost 45 times the work. JAX is left as it is: MJX-Warp's physics is not repeatable to
# the bit anyway, and the compiled scan wants one product.
CPU_BLOCK = 32


def rowwise(fn, *arrays):
    """fn on (batch, ...) NumPy arrays (None passes through), CPU_BLOCK rows at a time, padded with zeros to whole
    blocks; fn's outputs (an array or a tuple of arrays) are cut back to the batch. JAX arrays go to fn whole."""
    first = arrays[0]
    if not isinstance(first, np.ndarray) or first.size == 0:  # JAX, or no rows to block
        return fn(*arrays)
    single = first.ndim == 1  # one env's observation (the CPU gym env): a batch of one
    if single:
        arrays = tuple(None if a is None else a[None] for a in arrays)
    n = arrays[0].shape[0]
    pad = -n % CPU_BLOCK
    arrays = tuple(None if a is None else np.concatenate([a, np.zeros((pad,) + a.shape[1:], a.dtype)])
                   for a in arrays)
    blocks = [fn(*(None if a is None else a[i:i + CPU_BLOCK] for a in arrays)) for i in range(0, n + pad, CPU_BLOCK)]

    def joined(parts):
        out = np.concatenate(parts)[:n]
        return out[0] if single else out

    if isinstance(blocks[0], tuple):
        return tuple(joined([b[k] for b in blocks]) for k in range(len(blocks[0])))
    return joined(blocks)


def mlp(params: dict, meta: dict, act: str, x, pose=None):
    """Normalise by the checkpoint's mean and std, then the Dense layers, in x's array namespace and dtype
    (a pixel policy's first Dense layer reads its pose estimate's `pose_features`, then the normalised features)."""
    xp = array_namespace(x)
    h = (x - xp.asarray(meta["in_mean"], dtype=x.dtype)) / xp.asarray(meta["in_std"], dtype=x.dtype)
    if pose is not None:
        h = xp.concat([pose, h], axis=-1)
    params = {k: v for k, v in params.items() if k.startswith("Dense_")}
    for i in range(len(params)):
        layer = params[f"Dense_{i}"]
        h = h @ xp.asarray(layer["kernel"], dtype=x.dtype) + xp.asarray(layer["bias"], dtype=x.dtype)
        if i < len(params) - 1:
            h = activation(act, h, xp)
    return h
