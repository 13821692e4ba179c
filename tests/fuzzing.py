"""What the boundary fuzzers share (tests/test_fuzz_api.py, tests/test_fuzz_cli.py): the budget, the odd values,
and the one property every public entry must keep.

The property: a call either returns a valid result whose numbers are all finite, or raises the package's own
error (`MjxPushtError`) with a one-line message; anything else (a numpy ValueError, an AttributeError, a NaN
handed on) fails the test, and Hypothesis shrinks it to the smallest input that does.

Budget: FUZZ_EXAMPLES examples per entry (MJX_PUSHT_FUZZ_EXAMPLES overrides it: 2000 for a long search by hand),
derandomized (the same examples every CI run, no database to keep), each under a deadline.
"""

from __future__ import annotations

import datetime
import math
import os

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from mjx_pusht.errors import MjxPushtError

BIG = "MJX_PUSHT_FUZZ_EXAMPLES" in os.environ
FUZZ_EXAMPLES = int(os.environ.get("MJX_PUSHT_FUZZ_EXAMPLES", "50"))
FUZZ = settings(max_examples=FUZZ_EXAMPLES, derandomize=not BIG, database=None, print_blob=True,
                deadline=datetime.timedelta(seconds=20),  # a first call builds a model; CI's 2 cores are shared
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large, HealthCheck.filter_too_much])


class Opaque:
    """An object no entry knows (repr'd in messages, never converted)."""

    def __repr__(self) -> str:
        return "Opaque()"


# Values a careless or hostile caller hands over: every kind, the edges of each.
ODD_NUMBERS = st.one_of(
    st.sampled_from([0, -1, 1, 2**31, 2**63, 2**64, -(2**63), 10**30]),
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.sampled_from([math.nan, math.inf, -math.inf, 0.5, -0.0, 1e308, 5e-324]),
    st.booleans(), st.complex_numbers(max_magnitude=1e6), st.just(np.float32("nan")), st.just(np.int64(3)),
)
ODD = st.one_of(
    st.none(), ODD_NUMBERS, st.text(max_size=6), st.sampled_from(["", " ", "٣", "１", "nan", "cpu", "state", "\0"]),
    st.binary(max_size=3), st.builds(Opaque), st.builds(dict), st.builds(set),
    st.lists(ODD_NUMBERS, max_size=6),
    hnp.arrays(st.sampled_from([np.float64, np.float32, np.int64, np.bool_, np.complex128, np.uint8]),
               hnp.array_shapes(min_dims=0, max_dims=3, max_side=6)),
)


def arrays_near(shape: tuple) -> st.SearchStrategy:
    """Arrays of about `shape` (that shape most often, another sometimes) of every dtype and value (NaN, inf,
    the dtype's extremes), lists of odd numbers, and object arrays of them."""
    shapes = st.one_of(st.just(shape), st.just(shape), hnp.array_shapes(min_dims=0, max_dims=len(shape) + 1,
                                                                        max_side=6))
    numeric = hnp.arrays(st.sampled_from([np.float64, np.float32, np.int64, np.int8, np.bool_, np.complex128]),
                         shapes)
    objects = st.lists(ODD_NUMBERS, min_size=shape[-1] if shape else 0, max_size=shape[-1] if shape else 0)
    return st.one_of(numeric, objects, objects.map(lambda v: np.array(v + [None], dtype=object)[:-1]))


def finite(result, where: str = "result") -> None:
    """Every number in `result` (arrays, tuples, lists, dicts, NamedTuples, scalars) is finite."""
    if isinstance(result, dict):
        for k, v in result.items():
            finite(v, f"{where}[{k!r}]")
    elif isinstance(result, (tuple, list)):
        for i, v in enumerate(result):
            finite(v, f"{where}[{i}]")
    elif isinstance(result, np.ndarray) and result.dtype.kind in "fc":
        assert np.isfinite(result).all(), f"{where} holds non-finite values: {result}"
    elif isinstance(result, (float, complex, np.floating)):
        assert np.isfinite(result), f"{where} is {result}"


def holds(call, check=finite):
    """The property: `call()` returns a result that `check` accepts, or raises MjxPushtError in one line (then
    None). Any other exception propagates: the fuzzer's finding."""
    try:
        result = call()
    except MjxPushtError as e:
        message = str(e).strip()
        assert message and "\n" not in message, f"{type(e).__name__} is not one line: {message!r}"
        assert "Traceback" not in message, message
        return None
    check(result)
    return result


def snapshot(folder) -> dict:
    """Every entry under `folder` (hidden ones, symlinks and folders too) with its bytes or its link's target."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            p = os.path.join(root, name)
            out[os.path.relpath(p, folder)] = (("link", os.readlink(p)) if os.path.islink(p) else
                                               None if os.path.isdir(p) else open(p, "rb").read())
    return out
