"""Process-wide JAX settings the MJX backends need: the persistent compilation cache."""

from __future__ import annotations

import os
from pathlib import Path


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache so a second process does not compile again."""
    import jax

    from mjx_pusht.boundary import jax_cache

    cache = jax_cache(path)  # checked and made
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return cache
