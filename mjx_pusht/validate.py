"""One validation layer for what users hand the environments: the same input gets the same answer everywhere.

The gymnasium single and vector envs, the gym-pusht drop-in and the functional env all check
their inputs here: seeds, start states, reset masks and options, actions (shape, dtype,
finiteness, bounds), image sizes, render modes, counts and episode limits. A bad value is a
`ConfigError` (an `MjxPushtError` and a `ValueError`) whose one line names the argument and the
value; nothing is reshaped, cast from a wrong kind or silently replaced. Bounds are applied as
the action space says: actions are clipped to it (as gym-pusht's targets and the servos'
ctrlrange are), a start outside the walls is refused.

NumPy only: a CPU env must not need JAX (it may be forked). Device arrays are checked by a
reduction on their device (`actions_on_device`).
"""

from __future__ import annotations

import logging
import numbers

import numpy as np

from mjx_pusht.errors import ConfigError, ResetNeeded

SEED_MAX = 2**63 - 1  # task.reset.SEED_MAX (a seed is a non-negative int64)
# Bounds on what one run may ask for, checked before any work (the CLI's flags and the API's dataclasses alike):
# past them a run does not finish in any time anyone waits for, or its first array does not fit in memory (a
# 10**9-step schedule is a 16 GB control table, allocated before the first step; a hostile pass found it
# killing the process).
MAX_STEPS = 100_000  # control or schedule steps: 1,000 s of simulated time at 100 Hz
MAX_FRAME_SKIP = 1_000  # physics steps a control step
# physics steps one backend rollout runs (max_steps x frame_skip): 10,000 s at 100 Hz, what --max-steps 100,000 reaches
# at the default frame skip; --max-steps 100,000 at --frame-skip 1,000 was 10**8 steps an episode, hours a seed
MAX_PHYSICS_STEPS = 1_000_000
RENDER_MODES = (None, "rgb_array")
log = logging.getLogger("mjx_pusht")


from mjx_pusht.boundary import _show  # noqa: E402 - one way to show a value in a one-line message


def choice(name: str, value, options) -> object:
    """`value` if it is one of `options`, else a one-line error listing them (boundary.OneOf: an array or a list is
    compared as a value, never element by element)."""
    from mjx_pusht.boundary import OneOf

    return OneOf(tuple(options))(name, value)


def render_mode(value, human: bool = False) -> str | None:
    """None or 'rgb_array'; 'human' too where `human` (a single env, which opens its window up front)."""
    modes = RENDER_MODES + (("human",) if human else ())
    if value not in modes:
        raise ConfigError(f"render_mode must be {' or '.join(map(repr, modes))}, got {_show(value)}"
                          + ("" if human or value != "human" else " (a vector env has no window: use 'rgb_array')"))
    return value


def positive_int(name: str, value, low: int = 1, high: int | None = None) -> int:
    """An integer in [low, high] (bools and floats are refused, never truncated)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low or (
            high is not None and value > high):
        span = f"from {low}" + (f" to {high}" if high is not None else "")
        raise ConfigError(f"{name} must be an integer {span}, got {_show(value)}")
    return int(value)


def image_size(value, name: str = "image size") -> int:
    """An image side in pixels, an integer from 8 to 2048 (96.0 was taken, and reached gymnasium's Box as a float
    shape: a TypeError from the space)."""
    return positive_int(name, value, 8, 2048)


def episode_limit(value, name: str = "max_episode_steps") -> int | None:
    """A positive number of control steps, or None or -1: no limit (gymnasium's own meaning of -1: no TimeLimit)."""
    if value is None or (isinstance(value, numbers.Integral) and not isinstance(value, bool) and value == -1):
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ConfigError(f"{name} must be a positive integer (or -1 or None: no limit), got {_show(value)}")
    return int(value)


def threads(value, name: str = "threads") -> int | None:
    """None (the env picks) or a positive number of threads (0 is not 'the default': it is refused)."""
    return None if value is None else positive_int(name, value)


def pixels(value, name: str = "pixels") -> int:
    """0 (no images) or an image side from 8 to 2048."""
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and value == 0:
        return 0
    if not isinstance(value, numbers.Integral) or isinstance(value, bool) or not 8 <= value <= 2048:
        raise ConfigError(f"{name} must be 0 (no images) or an image size from 8 to 2048, got {_show(value)}")
    return int(value)


def fraction(name: str, value) -> float:
    """A real number in (0, 1] (a coverage threshold): NaN, 0 and anything past 1 would never or always end."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not 0 < float(value) <= 1:
        raise ConfigError(f"{name} must be a number in (0, 1], got {_show(value)}")
    return float(value)


def steps(name: str, value, high: int = MAX_STEPS) -> int:
    """A number of steps from 1 to `high` (MAX_STEPS: 1,000 s at 100 Hz), never a float or a bool."""
    return positive_int(name, value, 1, high)


def real_range(name: str, value, low: float, high: float, low_open: bool = False) -> float:
    """A finite real number in [low, high] ((low, high] where `low_open`), never a bool, a string or NaN."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not (
            (low < value if low_open else low <= value) and value <= high):
        span = f"{'(' if low_open else '['}{low:g}, {high:g}]"
        raise ConfigError(f"{name} must be a finite number in {span}, got {_show(value)}")
    return float(value)


def started(state, call: str = "step") -> None:
    """An env's `call` (step, render) needs its first reset to have run."""
    if state is None:
        raise ResetNeeded(f"call reset() before {call}(): the env has no episode yet")


def seed(value, name: str = "seed") -> int | None:
    """None or an integer from 0 to 2**63-1."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Integral)
                              or not 0 <= int(value) <= SEED_MAX):
        raise ConfigError(f"{name} must be an integer from 0 to 2**63-1, got {_show(value)}")
    return None if value is None else int(value)


def seed_list(value, n: int) -> list:
    """A vector env's seeds: None (each env's own), one integer s (env i gets s + i, as SyncVectorEnv seeds
    its copies) or a sequence of n (None or integer) seeds."""
    if value is None:
        return [None] * n
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        seed(value)
        return [seed(int(value) + i, "seed + env index") for i in range(n)]
    if isinstance(value, (str, bytes, dict)) or not hasattr(value, "__len__"):
        raise ConfigError(f"seed must be None, an integer or {n} integers, got {_show(value)}")
    out = list(np.asarray(value, object).reshape(-1)) if isinstance(value, np.ndarray) else list(value)
    if len(out) != n:
        raise ConfigError(f"seed: {len(out)} seeds for {n} environments")
    return [seed(s, f"seed[{i}]") for i, s in enumerate(out)]


def seed_array(value, name: str = "seeds") -> np.ndarray:
    """The functional env's and the backends' seeds: integers from 0 to 2**63-1, as a 1-D int64 array (floats and
    bools are refused, never truncated: [0.5, 1.7] is not seeds 0 and 1, nor [True, False] seeds 1 and 0)."""
    try:
        a = np.asarray(value)
    except ValueError:  # a ragged list
        raise ConfigError(f"{name} must be integers (a 1-D array), got {_show(value)}") from None
    if a.dtype == object:
        given = [seed(s, name) for s in a.reshape(-1)]
        if a.ndim == 0 or None in given:  # None: no seeds at all, or a None among them (the fuzzer's find)
            raise ConfigError(f"{name} must be integers (a 1-D array), got {_show(value)}")
        a = np.asarray(given, np.int64).reshape(a.shape)
    if a.dtype.kind not in "iu" or a.ndim > 1:
        raise ConfigError(f"{name} must be integers (a 1-D array), got {a.dtype} of shape {a.shape}")
    if a.size and (a.min() < 0 or (a.dtype.kind == "u" and a.max() > SEED_MAX)):
        bad = a[(a < 0) | (a > SEED_MAX)][0] if a.dtype.kind == "i" else a.max()
        raise ConfigError(f"{name} must be integers from 0 to 2**63-1, got {bad}")
    return a.astype(np.int64).reshape(-1)


def mask(value, n: int, name: str = "reset_mask") -> np.ndarray:
    """(n,) booleans, as documented (integers, 0/1 too, and floats are refused, never cast: np.array([1, 0, 1]) was
    taken as a mask while a float one was refused)."""
    try:
        a = np.asarray(value)
    except ValueError:  # a ragged list
        raise ConfigError(f"{name} must be ({n},) booleans, got {_show(value)}") from None
    if a.shape != (n,) or a.dtype != bool:
        raise ConfigError(f"{name} must be ({n},) booleans, got {a.dtype} of shape {a.shape}")
    return a.astype(bool)


def reset_options(options, known: tuple, where: str) -> dict:
    """The reset options this env uses. The options others are known to pass and this env does not read
    (boundary.FOREIGN_RESET_OPTIONS: LeRobot's rollout passes {"lerobot_new_rollout": True}) are ignored, logged at
    debug level; any other key is refused (a misspelt "reset_to_sate" was ignored: the episode started elsewhere)."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ConfigError(f"options must be a dict (or None), got {_show(options)}")
    from mjx_pusht.boundary import reset_options as honoured

    honoured(options, known, where)  # this package's options that `where` cannot honour are refused, not ignored
    from mjx_pusht.boundary import FOREIGN_RESET_OPTIONS, RESET_OPTIONS

    unknown = sorted(map(repr, set(options) - set(known) - set(FOREIGN_RESET_OPTIONS) - set(RESET_OPTIONS)))
    if unknown:
        raise ConfigError(f"{where}.reset takes no option {', '.join(unknown)}; it reads {', '.join(known)} (and "
                          f"ignores {', '.join(FOREIGN_RESET_OPTIONS)}, which LeRobot passes)")
    unused = sorted(map(str, set(options) - set(known)))
    if unused:
        log.debug("%s.reset ignores option(s) it does not use: %s", where, ", ".join(unused))
    return {k: v for k, v in options.items() if k in known and v is not None}


def starts(value, rows: int, lo, hi, what: str = "[tee x, y, yaw, pusher x, y]") -> np.ndarray:
    """reset_to_state: (5,) for every reset row or (rows, 5), finite, positions within [lo, hi] per column
    (the walls; NaN bounds for columns that are angles). Returns (rows, 5) float64."""
    try:
        a = np.asarray(value)
        if a.dtype.kind not in "fiu" and a.dtype != object:  # bools were 0 and 1, complex its real part
            raise TypeError(a.dtype)
        a = a.astype(np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"reset_to_state is {what}: real numbers, got {_show(value)}") from None
    if a.shape not in ((5,), (rows, 5)):
        raise ConfigError(f"reset_to_state is {what}: shape (5,) or ({rows}, 5), got {a.shape}")
    a = np.broadcast_to(a, (rows, 5))
    bad = ~np.isfinite(a).all(axis=1)
    if bad.any():
        raise ConfigError(f"reset_to_state must be finite numbers; row(s) {_rows(bad)}: {_show(a[bad][0].tolist())}")
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    check = ~np.isnan(lo)
    out = ((a < lo) | (a > hi)) & check
    if out.any():
        r = np.flatnonzero(out.any(axis=1))
        raise ConfigError(f"reset_to_state {what} puts a body outside the walls (positions run from "
                          f"{lo[check].min():g} to {hi[check].max():g}); row(s) {_rows(out.any(axis=1))}: "
                          f"{_show(a[r[0]].tolist())}")
    return a


def _rows(bad: np.ndarray) -> str:
    r = np.flatnonzero(bad)
    return ", ".join(map(str, r[:8])) + (f" and {len(r) - 8} more" if len(r) > 8 else "")


def actions(value, shape: tuple, low, high, what: str = "(x, y)") -> np.ndarray:
    """Host actions: the exact `shape` (never reshaped: that would scramble environments), real numbers,
    finite (a NaN or inf names its rows: a policy bug must not look like a pusher standing still),
    clipped to the action space [low, high]. Returns float64."""
    a = np.asarray(value)
    if a.shape != shape:
        n = f"one {what} per environment" if len(shape) == 2 else f"one {what}"
        raise ConfigError(f"actions must have shape {shape}, {n}; got shape {a.shape} "
                          "(never reshaped: that would scramble the environments)" if len(shape) == 2 else
                          f"an action is {n}, shape {shape}; got shape {a.shape}")
    if a.dtype.kind not in "fiu":
        raise ConfigError(f"actions must be real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    finite = np.isfinite(a)
    if not finite.all():
        raise ConfigError(f"actions must be finite: {_nonfinite(finite, a)}")
    return np.minimum(np.maximum(a, low), high)  # np.clip's own checks cost more than the step's physics


def action_pair(value, low: float, high: float, what: str = "(x, y)") -> tuple[float, float]:
    """One env's action as two floats: `actions(value, (2,), low, high, what)`'s values (and its errors), without
    its array calls for the usual input, a NumPy (2,) float32 or float64 array (a single env's step)."""
    if type(value) is np.ndarray and value.shape == (2,) and value.dtype in _FLOATS:
        x, y = value.tolist()  # float32 to float64 exactly, as astype does
        if x - x == 0 and y - y == 0:  # finite (inf - inf and NaN are NaN)
            lo, hi = float(low), float(high)
            return min(max(x, lo), hi), min(max(y, lo), hi)  # np.minimum(np.maximum()) on floats
    x, y = actions(value, (2,), low, high, what).tolist()
    return x, y


_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))


def _nonfinite(finite: np.ndarray, a) -> str:
    if finite.ndim == 1:
        return f"got {_show(np.asarray(a).tolist())}"
    bad = ~finite.all(axis=1)
    first = np.asarray(a)[np.flatnonzero(bad)[0]]
    return f"row(s) {_rows(bad)} (of {len(bad)}) hold non-finite values, e.g. {_show(first.tolist())}"


def actions_on_device(a, n: int, xp) -> None:
    """A device batch of actions (JAX): shape (n, 2) and finite, checked by one reduction on the device."""
    actions_shape_on_device(a, n)
    finite = xp.isfinite(a)
    if not bool(xp.all(finite)):
        f = np.asarray(finite)
        raise ConfigError(f"actions must be finite: {_nonfinite(f, np.asarray(a))}")


def actions_shape_on_device(a, n: int) -> None:
    """A device batch's shape and dtype (no look at its values: that would wait for the device)."""
    if tuple(a.shape) != (n, 2):
        raise ConfigError(f"actions must have shape ({n}, 2), one (x, y) per environment; got {tuple(a.shape)} "
                          "(never reshaped: that would scramble the environments)")
    if not np.issubdtype(np.dtype(a.dtype), np.number) or np.dtype(a.dtype).kind == "c":
        raise ConfigError(f"actions must be real numbers, got dtype {a.dtype}")


def deferred_nonfinite(flags: list) -> None:
    """Raise for the first of `flags` (step number, per-row non-finite flags, the actions, all on the device) that
    holds a non-finite action: read where the host waits for the device anyway, never once a step."""
    for step, bad, a in flags:
        b = np.asarray(bad)
        if b.any():
            raise ConfigError(f"actions must be finite: at step {step} since reset, "
                              f"{_nonfinite(~b[:, None].repeat(2, 1), np.asarray(a))} (those rows were held still "
                              "from that step on; the error is raised where the host next reads the batch)")
