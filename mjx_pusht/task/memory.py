"""How an expert's int32 carry reads as a student's memory (train/policy.py): a move class and latch bits.

A DAgger student learns to keep its teacher's carry (train/dagger.py): it sees the carry as features (a one-hot of
the move, then each latch bit) and predicts the next one (a softmax over the moves, a sigmoid a latch). The format
is the teacher's: the chapter's expert keeps its move (none yet, rotate, push x, push y) in the low bits and two
latches above them; gym-pusht's expert keeps the index of the contact it pursues (-1: none yet), its move class
being index + 1, with no latches.
"""

from __future__ import annotations

import dataclasses

from mjx_pusht.task.rules import array_namespace


@dataclasses.dataclass(frozen=True)
class CarryFormat:
    moves: int = 4  # move classes: (carry + offset) below the lowest latch bit, in [0, moves)
    latches: tuple[int, ...] = (16, 32)  # single bits above the move's
    offset: int = 0

    @property
    def size(self) -> int:
        """Its width in the features and in the network's memory head."""
        return self.moves + len(self.latches)

    def move(self, carry):
        xp = array_namespace(carry)
        c = xp.astype(carry, xp.int32) + self.offset
        return c & (min(self.latches) - 1) if self.latches else c

    def bits(self, carry) -> list:
        xp = array_namespace(carry)
        return [(xp.astype(carry, xp.int32) & b) != 0 for b in self.latches]

    def encode(self, carry, dtype):
        """(..., size): the move's one-hot, then the latch bits, as `dtype`."""
        xp = array_namespace(carry)
        move = self.move(carry)
        return xp.stack([xp.astype(move == k, dtype) for k in range(self.moves)]
                        + [xp.astype(b, dtype) for b in self.bits(carry)], axis=-1)

    def carry(self, logits):
        """The carry a memory head (..., size) of logits keeps: its likeliest move and each latch it sets."""
        xp = array_namespace(logits)
        out = xp.astype(xp.argmax(logits[..., : self.moves], axis=-1), xp.int32) - self.offset
        for i, bit in enumerate(self.latches):
            out = out | xp.where(logits[..., self.moves + i] > 0, bit, 0)
        return xp.astype(out, xp.int32)

    def meta(self) -> dict:
        return dataclasses.asdict(self) | {"latches": list(self.latches)}

    @classmethod
    def of(cls, meta: dict | None) -> "CarryFormat":
        """A checkpoint's format (its meta["memory"]); the chapter's for one written before formats existed."""
        spec = (meta or {}).get("memory")
        if not spec:
            return CHAPTER
        return cls(int(spec["moves"]), tuple(int(b) for b in spec["latches"]), int(spec["offset"]))


CHAPTER = CarryFormat()  # task/controllers.Expert: move 0-3 in the low bits, NEAR (16) and REVERSE (32)
