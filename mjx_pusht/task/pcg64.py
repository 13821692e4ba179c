"""NumPy's `default_rng(seed)` uniform stream, computed for many seeds at once.

Seeding a NumPy generator costs ~20 us, 20 s for a million seeds. Both steps it takes are
public, fixed algorithms, so they vectorise over seeds in uint64 arithmetic:
- `SeedSequence(seed)` hashes the seed's 32-bit words into a 4-word pool and draws 8 words
  from it (numpy/random/bit_generator.pyx: hashmix, mix, generate_state);
- `PCG64` takes them as a 128-bit state and increment (pcg64_set_seed) and steps
  state = state * MULT + inc mod 2**128, giving the XSL-RR output of each new state; a
  double is (next >> 11) * 2**-53 (pcg64.h, distributions.c).
The result equals `np.random.default_rng(seed).random(n)` bit for bit (tested over many seeds).
"""

from __future__ import annotations

import numpy as np

from mjx_pusht.errors import ConfigError

_U32 = np.uint64(0xFFFFFFFF)
INIT_A, MULT_A = 0x43B0D7E5, 0x931E8875
INIT_B, MULT_B = 0x8B51F9DD, 0x58F38DED
MIX_MULT_L, MIX_MULT_R = 0xCA01F9DD, 0x4973F715
XSHIFT = 16
PCG_MULT = (0x2360ED051FC65DA4, 0x4385DF649FCCF645)  # PCG_DEFAULT_MULTIPLIER_128 as (high, low)


def _u32(x):
    return np.asarray(x, np.uint64) & _U32


def _hashmix(value, hash_const: int):
    """SeedSequence's hashmix on uint32 values held in uint64 arrays; returns (value, next hash_const)."""
    value = _u32(value ^ np.uint64(hash_const))
    hash_const = (hash_const * MULT_A) & 0xFFFFFFFF
    value = _u32(value * np.uint64(hash_const))
    return value ^ (value >> np.uint64(XSHIFT)), hash_const


def _mix(x, y):
    r = _u32(np.uint64(MIX_MULT_L) * x - np.uint64(MIX_MULT_R) * y)
    return r ^ (r >> np.uint64(XSHIFT))


def _seed_state(seeds: np.ndarray) -> list[np.ndarray]:
    """generate_state(4, uint64) of SeedSequence(seed) for each seed: four (N,) uint64 arrays."""
    s = seeds.astype(np.uint64)
    # A seed's entropy is its 32-bit words, low first (one word below 2**32). The pool of 4 words
    # hashes missing words as 0, so [lo, hi, 0, 0] gives the same pool whether hi is present or not.
    words = [s & _U32, s >> np.uint64(32), np.zeros_like(s), np.zeros_like(s)]
    hc = INIT_A
    pool = []
    for w in words:
        v, hc = _hashmix(w, hc)
        pool.append(v)
    for src in range(4):
        for dst in range(4):
            if src != dst:
                h, hc = _hashmix(pool[src], hc)
                pool[dst] = _mix(pool[dst], h)
    hb = INIT_B
    out32 = []
    for i in range(8):  # 4 uint64 words = 8 uint32 words, cycling through the pool
        v = pool[i % 4] ^ np.uint64(hb)
        hb = (hb * MULT_B) & 0xFFFFFFFF
        v = _u32(v * np.uint64(hb))
        out32.append(v ^ (v >> np.uint64(XSHIFT)))
    return [out32[2 * k] | (out32[2 * k + 1] << np.uint64(32)) for k in range(4)]  # little-endian pairs


def _mul64(a, b):
    """Full 64 x 64 -> 128-bit products of uint64 arrays, as (high, low)."""
    a0, a1 = a & _U32, a >> np.uint64(32)
    b0, b1 = b & _U32, b >> np.uint64(32)
    p00, p01, p10, p11 = a0 * b0, a0 * b1, a1 * b0, a1 * b1
    mid = (p00 >> np.uint64(32)) + (p01 & _U32) + (p10 & _U32)
    lo = (p00 & _U32) | (mid << np.uint64(32))
    hi = p11 + (p01 >> np.uint64(32)) + (p10 >> np.uint64(32)) + (mid >> np.uint64(32))
    return hi, lo


def _add128(ah, al, bh, bl):
    lo = al + bl
    return ah + bh + (lo < al).astype(np.uint64), lo


def _mul128(ah, al, bh: int, bl: int):
    """(ah, al) * (bh, bl) mod 2**128."""
    bh_, bl_ = np.uint64(bh), np.uint64(bl)
    hi, lo = _mul64(al, np.full_like(al, bl_))
    return hi + ah * bl_ + al * bh_, lo


class Streams:
    """PCG64 generators for many seeds, advanced together."""

    def __init__(self, seeds):
        seeds = np.asarray(seeds, np.int64).reshape(-1)
        if (seeds < 0).any():
            raise ConfigError("seeds must be non-negative")
        with np.errstate(over="ignore"):
            s0, s1, i0, i1 = _seed_state(seeds)
            # pcg64_set_seed: state constant (s0, s1), increment ((i0, i1) << 1) | 1, then srandom's two steps
            self.inc_hi = (i0 << np.uint64(1)) | (i1 >> np.uint64(63))
            self.inc_lo = (i1 << np.uint64(1)) | np.uint64(1)
            self.hi, self.lo = np.zeros_like(s0), np.zeros_like(s0)
            self._step()
            self.hi, self.lo = _add128(self.hi, self.lo, s0, s1)
            self._step()

    def subset(self, rows: np.ndarray) -> "Streams":
        """The streams of some rows only (advancing it leaves the others where they were)."""
        new = object.__new__(Streams)
        for k in ("hi", "lo", "inc_hi", "inc_lo"):
            setattr(new, k, getattr(self, k)[rows])
        return new

    def _step(self) -> None:
        hi, lo = _mul128(self.hi, self.lo, *PCG_MULT)
        self.hi, self.lo = _add128(hi, lo, self.inc_hi, self.inc_lo)

    def next64(self) -> np.ndarray:
        with np.errstate(over="ignore"):
            self._step()
            x = self.hi ^ self.lo
            r = self.hi >> np.uint64(58)  # state >> 122
            return np.where(r == 0, x, (x >> r) | (x << ((np.uint64(64) - r) & np.uint64(63))))

    def random(self) -> np.ndarray:
        """The next double in [0, 1) of every stream, as Generator.random() draws it."""
        return (self.next64() >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)

    def uniform(self, low: float, high: float) -> np.ndarray:
        """Generator.uniform(low, high): low + (high - low) * next double."""
        return low + (high - low) * self.random()
