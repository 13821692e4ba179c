"""Seed specs: a count N (0..N-1), a range A:B (A..B-1), or a list a,b,c."""

from __future__ import annotations

import numpy as np

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.task.reset import SEED_MAX as MAX_SEED


class SeedSpecError(MjxPushtError, ValueError):
    pass


def _int(text: str, spec: str) -> int:
    try:
        value = int(text.strip())
    except ValueError:
        raise SeedSpecError(f"malformed --seeds {spec!r}: {text.strip()!r} is not an integer") from None
    if value < 0 or value > MAX_SEED:
        raise SeedSpecError(f"malformed --seeds {spec!r}: seeds are integers from 0 to 2**63-1, got {value}")
    return value


def parse_seeds(spec: str) -> np.ndarray:
    """The seeds a spec names, as int64, in the order given; empty or duplicated specs are errors."""
    spec = spec.strip()
    if not spec:
        raise SeedSpecError("--seeds is empty: give a count N, a range A:B or a list a,b,c")
    if ":" in spec:
        parts = spec.split(":")
        if len(parts) != 2:
            raise SeedSpecError(f"malformed --seeds {spec!r}: a range is A:B")
        lo, hi = _int(parts[0], spec), _int(parts[1], spec)
        if hi <= lo:
            raise SeedSpecError(f"--seeds {spec!r} is an empty range: B must be greater than A")
        return np.arange(lo, hi, dtype=np.int64)
    if "," in spec:
        seeds = np.array([_int(p, spec) for p in spec.split(",")], dtype=np.int64)
        if len(np.unique(seeds)) != len(seeds):
            raise SeedSpecError(f"--seeds {spec!r} lists a seed twice")
        return seeds
    n = _int(spec, spec)
    if n == 0:
        raise SeedSpecError("--seeds 0 is an empty sweep: give a positive count")
    return np.arange(n, dtype=np.int64)
