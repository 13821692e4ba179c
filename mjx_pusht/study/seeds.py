"""Seed specs: a count N (0..N-1), a range A:B (A..B-1), or a list a,b,c."""

from __future__ import annotations

import numpy as np

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.task.reset import SEED_MAX as MAX_SEED


class SeedSpecError(MjxPushtError, ValueError):
    """A --seeds spec that names no seeds, malformed ones, or too many; the message says which."""


# One run's rows fit in memory: 2**30 seeds is 8.6 GB of seeds alone. NumPy's arange of a count near
# 2**63 silently comes back empty (a sweep then wrote an empty table and exited 0), and 10**10 dies
# allocating: both are refused here, before any work. Larger studies: A:B ranges per run.
MAX_SEEDS = 1 << 30


def _int(text: str, spec: str, end: bool = False) -> int:
    """A seed of `spec`; `end`: a range's end, which is past its last seed (so 2**63 reaches the last legal one)."""
    try:
        value = int(text.strip())
    except ValueError:
        raise SeedSpecError(f"malformed --seeds {spec!r}: {text.strip()!r} is not an integer") from None
    if value < 0 or value > MAX_SEED + end:
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
        lo, hi = _int(parts[0], spec), _int(parts[1], spec, end=True)
        if hi <= lo:
            raise SeedSpecError(f"--seeds {spec!r} is an empty range: B must be greater than A")
        _check_count(hi - lo, spec)
        return np.arange(hi - lo, dtype=np.int64) + np.int64(lo)  # hi itself may be 2**63, past int64
    if "," in spec:
        seeds = np.array([_int(p, spec) for p in spec.split(",")], dtype=np.int64)
        if len(np.unique(seeds)) != len(seeds):
            raise SeedSpecError(f"--seeds {spec!r} lists a seed twice")
        return seeds
    n = _int(spec, spec)
    if n == 0:
        raise SeedSpecError("--seeds 0 is an empty sweep: give a positive count")
    _check_count(n, spec)
    return np.arange(n, dtype=np.int64)


def _check_count(n: int, spec: str) -> None:
    if n > MAX_SEEDS:
        raise SeedSpecError(f"--seeds {spec!r} asks for {n:,} seeds; one run takes at most 2**30 "
                            f"({MAX_SEEDS:,}): split the study into A:B ranges")
    from mjx_pusht.boundary import BYTES_PER_SEED, fits

    fits(f"--seeds {spec!r} ({n:,} seeds)", n, BYTES_PER_SEED, "split the study into A:B ranges, one run each",
         error=SeedSpecError)
