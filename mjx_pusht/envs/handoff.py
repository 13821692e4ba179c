"""Handing arrays over without copies: JAX arrays as they are, PyTorch tensors through DLPack, NumPy when asked.

A torch tensor made by `to_torch` is a view of the JAX array's device memory (same pointer, no
host round trip), so a PyTorch policy on the same GPU reads the environment's observations where
they lie. NumPy is a copy to the host by nature; it is what the CPU backend has anyway.
"""

from __future__ import annotations

from mjx_pusht import boundary
from mjx_pusht.errors import ConfigError

ARRAY_TYPES = ("jax", "torch", "numpy")


def check_array_type(array_type: str) -> str:
    boundary.OneOf(tuple(ARRAY_TYPES))("array_type", array_type)  # an array is refused, not compared
    if array_type == "torch":
        try:
            import torch  # noqa: F401
        except ImportError:
            raise ConfigError("array_type='torch' needs PyTorch: pip install torch") from None
    return array_type


def to_torch(x):
    """A JAX (or NumPy) array as a torch tensor on the same device, sharing its memory (DLPack)."""
    import torch

    return torch.from_dlpack(x)


def hand_off(tree, array_type: str):
    """Every array in `tree` as `array_type`: jax (unchanged), torch (DLPack views), numpy (one host transfer)."""
    import jax

    if array_type == "jax":
        return tree
    if array_type == "numpy":
        return jax.device_get(tree)
    return jax.tree.map(to_torch, tree)


def from_user(x):
    """An action from a user: a torch tensor comes in through DLPack (no copy on the same device), else as is."""
    if type(x).__module__.startswith("torch"):
        import jax.numpy as jnp

        return jnp.from_dlpack(x.detach().contiguous())
    return x
