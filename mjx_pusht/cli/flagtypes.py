"""The flags' value types: each turns a flag's text into its value, or refuses it in one line (argparse's
ArgumentTypeError, which the parser prints as `argument --flag: ...`). Bounds come from the API's own rules."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from mjx_pusht import validate
from mjx_pusht.boundary import MAX_ENVS
from mjx_pusht.errors import MjxPushtError


def int_at_least(low: int, high: int | None = None, why: str = ""):
    """An argparse type: an integer >= low (and <= high, `why` saying what the bound keeps off), with a one-line
    message otherwise."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if v < low:
            raise argparse.ArgumentTypeError(f"must be an integer >= {low}, got {v}")
        if high is not None and v > high:
            raise argparse.ArgumentTypeError(f"must be an integer from {low} to {high:,}{why}, got {v:,}")
        return v

    return parse


# counts a jitted program takes (fit steps, minibatches, iterations): past 2**31-1 JAX's int32 overflowed in a traceback
positive = int_at_least(1, 2**31 - 1)
rows = int_at_least(1, MAX_ENVS, " rows at once")  # a batch's rows (boundary.MAX_ENVS: one batch's first arrays)
nonneg = int_at_least(0)
# The API's bounds (validate.MAX_STEPS, MAX_FRAME_SKIP: why they are there), as flag types
steps = int_at_least(1, validate.MAX_STEPS, " (1,000 s of simulated time at 100 Hz)")
frame_skip = int_at_least(1, validate.MAX_FRAME_SKIP, " physics steps a control step")
worlds = int_at_least(1, 1 << 22, " episodes at once")


def positive_or_off(text: str, high: float = math.inf) -> float | str:
    """An argparse type: a finite float in (0, high], or "off"."""
    if text == "off":
        return text
    try:
        v = positive_float(text)
    except argparse.ArgumentTypeError:
        v = None
    if v is None or v > high:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0{f' and <= {high:g}' if high < math.inf else ''} "
                                         f"or 'off', got {text}") from None
    return v


def video_file(text: str) -> Path:
    """An argparse type: a file's path (`v.gif/` named a folder, and Path() dropped the slash: the file was written)."""
    if text.endswith("/"):
        raise argparse.ArgumentTypeError(f"{text!r} names a folder (it ends in /): give a file such as "
                                          f"{text}episodes.gif")
    return Path(text)


def learning_rate(text: str) -> float:
    """An argparse type: Adam's step size, > 0 and a float32 (1e308 overflowed in JAX's cast with a warning; a rate
    too large to train is caught by its first fit's NaN loss, in one line)."""
    v = positive_float(text)
    if v > 1e38:
        raise argparse.ArgumentTypeError(f"must be a learning rate > 0 and at most 1e38 (a float32), got {text}")
    return v


def _number(text: str, ok, rule: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not ok(v):
        raise argparse.ArgumentTypeError(f"must be {rule}, got {text}")
    return v


def positive_float(text: str) -> float:
    """An argparse type: a finite float > 0."""
    return _number(text, lambda v: math.isfinite(v) and v > 0, "a finite number > 0")


def fraction(text: str) -> float:
    """An argparse type: a number from 0 to 1."""
    return _number(text, lambda v: 0.0 <= v <= 1.0, "a fraction from 0 to 1")


def in_unit(what: str):
    """An argparse type: a number in (0, 1] (validate.fraction's rule: 0, NaN and 1.5 refused), named `what` in the
    error: a coverage (--success-threshold) or a success rate (train --until: a rate of 0 is met before training)."""
    def parse(text: str) -> float:
        try:
            return validate.fraction(what, float(text))
        except (ValueError, MjxPushtError):
            raise argparse.ArgumentTypeError(f"must be {what} in (0, 1], got {text}") from None
    return parse


threshold, rate = in_unit("a coverage"), in_unit("a success rate")


def widths(text: str) -> tuple[int, ...]:
    """An argparse type: comma-separated positive layer widths."""
    try:
        widths = tuple(int(w) for w in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of integers like 256,256") from None
    if not widths or min(widths) < 1 or max(widths) > 65536:
        raise argparse.ArgumentTypeError(f"layer widths must be integers from 1 to 65,536, got {text!r}")
    return widths


def folder(text: str) -> Path:
    """An argparse type: a folder's path, never empty (an empty --out was the current folder, written into)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("is empty: give a folder, such as outputs/run")
    return Path(text)


def seed(text: str) -> int:
    v = nonneg(text)
    from mjx_pusht.task.reset import SEED_MAX

    if v > SEED_MAX:
        raise argparse.ArgumentTypeError("seeds are integers from 0 to 2**63-1")
    return v


def train_seed(text: str) -> int:
    """A training seed: JAX's key takes 32 bits of it (with 64-bit types off, as here), so seeds 2**31 apart would
    start the same networks: refused, not folded."""
    v = nonneg(text)
    if v > 2**31 - 1:
        raise argparse.ArgumentTypeError(f"training seeds are integers from 0 to 2**31-1 (JAX's key), got {v}")
    return v
