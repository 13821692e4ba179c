"""A controller's actions are checked for finiteness before they drive the physics, on every backend.

A NaN or inf action is not a policy that fails to push: MuJoCo C resets a world whose ctrl is
bad (mjWARN_BADCTRL) and MJX steps NaN into the state, so either way an eval would read as a
plain 0% success. Both backends keep the same per-row record, `{"step", "value"}`: the first
control step at which the row's live episode got a non-finite action (-1: none) and that
action. The CPU backend folds it in and checks it every control step, on the host; MJX folds
it into the carry of its compiled scan and checks it when the chunk comes back, so there is
no host round trip per step. A row's bad action is replaced by zero before the physics sees
it (on the CPU the run has stopped by then; on MJX the row steps on, and its chunk is refused).
"""

from __future__ import annotations

import numpy as np

from mjx_pusht.task.controllers import ControllerError


class NonFiniteActionError(ControllerError):
    """A controller returned a NaN or infinite action for a live episode; the run stopped there."""

    def __init__(self, controller: str, seed: int, step: int, value, after: str = ""):
        # the fields are the exception's args, so it crosses a process boundary (FeedbackPool's workers) whole;
        # `after`: what the caller adds (where the finished chunks are)
        super().__init__(controller, int(seed), int(step), tuple(float(v) for v in value), after)

    controller = property(lambda self: self.args[0])
    seed = property(lambda self: self.args[1])
    step = property(lambda self: self.args[2])
    value = property(lambda self: self.args[3])

    def __str__(self) -> str:
        value = ", ".join(repr(v) for v in self.value)
        return (f"controller {self.controller} returned a non-finite action [{value}] at control step {self.step} "
                f"of seed {self.seed}; the run stopped before it drove the physics{self.args[4]}")


def record_init(batch_shape, dtype, xp) -> dict:
    """No bad action yet: step -1 and a zero value per row (`batch_shape` () for one world under vmap)."""
    return {"step": xp.full(batch_shape, -1, dtype=xp.int32), "value": xp.zeros((*batch_shape, 2), dtype=dtype)}


def record_update(record: dict, action, live, k, xp):
    """Fold control step k's `action` into `record` (its first non-finite action per live row); returns the
    action with those rows zeroed, so nothing non-finite reaches the physics, and the new record."""
    bad = live & ~xp.all(xp.isfinite(action), axis=-1)
    first = bad & (record["step"] < 0)
    record = {"step": xp.where(first, xp.astype(xp.asarray(k), xp.int32), record["step"]),
              "value": xp.where(first[..., None], xp.astype(action, record["value"].dtype), record["value"])}
    return xp.where(bad[..., None], xp.zeros_like(action), action), record


def check(record: dict | None, seeds, controller: str) -> None:
    """Raise `NonFiniteActionError` for the earliest bad control step of `record` (host arrays), at the first
    row in seed order that had one then; nothing when every action was finite (or nothing was checked: None)."""
    if record is None:
        return
    step = np.asarray(record["step"])
    rows = np.flatnonzero(step >= 0)
    if len(rows):
        row = rows[np.argmin(step[rows])]  # argmin takes the first row of the smallest step
        raise NonFiniteActionError(controller, seeds[row], step[row], np.asarray(record["value"])[row])


def as_numbers(action, controller: str) -> np.ndarray:
    """A CPU controller's action as float64, or a one-line error when it is not numbers (None, strings)."""
    try:
        return np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ControllerError(f"controller {controller} returned an action that is not numbers "
                              f"({type(e).__name__}: {str(e).splitlines()[0]})") from None


def earliest(errors: list[NonFiniteActionError]) -> NonFiniteActionError:
    """Of the errors of consecutive slices of one batch (in row order), the one a single process would raise:
    the earliest control step, then the first slice."""
    return min(errors, key=lambda e: e.step)
