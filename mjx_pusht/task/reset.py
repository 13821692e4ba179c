"""The reset contract: seed -> start pose, the single source of start poses for every backend.

Two distributions, each drawn from one PCG64 generator per seed (`np.random.default_rng(seed)`),
so seed s starts the same in a batch of a million as alone, on every backend:

- `chapter`: the chapter's reset. x, then y, then yaw of the tee, in that order, from small
  ranges just north of the target; the pusher starts at (0, -0.25).
- `task`: gym-pusht's random start. The tee anywhere in the walled workspace at any yaw, clear
  of the walls (x, y, yaw drawn in that order); then up to `PUSHER_TRIES` pusher positions
  (x, y pairs) anywhere in the workspace, the first one clear of the tee taken.
- `gym-pusht`: gym-pusht's own reset, for the gym-pusht scene: its five draws (agent x, y and
  block x, y as integer pixels, then the angle) from the same generator, placed as it places
  them (model/gym_pusht.py), so a seed starts where gym-pusht's `reset(seed=seed)` does.
- `easy`: a start to debug a policy on (gym-pusht#18 asks for "a trivial variant"), on either scene:
  the tee 1.5 to 4 cm from the target in any direction (distance, then direction), its yaw within
  +-0.3 rad, then the pusher just clear of the T's reach in any direction (an angle). Never covered
  at reset (the most covered of 200,000 seeds' starts is 0.78: the 1.5 cm alone uncovers the T well
  past 5%; test), and both tasks' experts
  succeed from it in a few dozen control steps (docs/task.md).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mjx_pusht import boundary
from mjx_pusht.errors import ConfigError
from mjx_pusht.model.layout import PUSHER_START_Y
from mjx_pusht.task.rules import T_REACH, distance_to_tee

# numpy's SeedSequence takes any non-negative int; the tables' int64 seed column holds up to this
SEED_MAX = 2**63 - 1

TEE_X_RANGE = (-0.03, 0.03)
TEE_Y_RANGE = (0.02, 0.06)
TEE_YAW_RANGE = (-0.2, 0.2)
RESETS = ("chapter", "task", "gym-pusht", "easy")

# task: the walls' inner faces are at +-0.39 m. A tee centre within TASK_TEE_HALF keeps every point
# of the T (reach 0.106 m) 1 cm clear of them; a pusher centre within TASK_PUSHER_HALF keeps the
# cylinder (radius 0.015 m) 1.5 cm clear, and CLEARANCE keeps it that far from the tee's outline.
TASK_TEE_HALF = 0.27
TASK_PUSHER_HALF = 0.36
PUSHER_RADIUS = 0.015
CLEARANCE = 0.01
PUSHER_TRIES = 16  # a draw lands on the (inflated) T with p < 0.05, so 16 tries all fail with p < 1e-20

# easy: the tee's offset from the target (m) and its yaw (rad); the pusher this far from the tee's origin, clear of
# every point of the T (T_REACH) by CLEARANCE: 0.131 m, inside either scene's walls from a tee this near the target
EASY_OFFSET = (0.015, 0.04)
EASY_YAW = 0.3
EASY_PUSHER = T_REACH + PUSHER_RADIUS + CLEARANCE


def start_pose(seed: int) -> tuple[float, float, float]:
    """The tee's (x, y, yaw) start for one seed, drawn exactly as the chapter draws it."""
    rng = np.random.default_rng(seed)
    x = float(rng.uniform(*TEE_X_RANGE))
    y = float(rng.uniform(*TEE_Y_RANGE))
    yaw = float(rng.uniform(*TEE_YAW_RANGE))
    return x, y, yaw


def task_start(seed: int) -> tuple[float, float, float, float, float]:
    """The task reset for one seed: tee (x, y, yaw) anywhere clear of the walls, then the pusher clear of the tee."""
    rng = np.random.default_rng(seed)
    x = float(rng.uniform(-TASK_TEE_HALF, TASK_TEE_HALF))
    y = float(rng.uniform(-TASK_TEE_HALF, TASK_TEE_HALF))
    yaw = float(rng.uniform(-np.pi, np.pi))
    tries = rng.uniform(-TASK_PUSHER_HALF, TASK_PUSHER_HALF, size=(PUSHER_TRIES, 2))
    clear = distance_to_tee(tries, np.array([x, y, yaw])[None]) > PUSHER_RADIUS + CLEARANCE
    px, py = tries[int(np.argmax(clear)) if clear.any() else PUSHER_TRIES - 1]  # the first clear one (the last if none)
    return x, y, yaw, float(px), float(py)


def start_state(seed: int, reset: str = "chapter") -> tuple[float, ...]:
    """Tee (x, y, yaw) and pusher (x, y) at reset for one seed."""
    if reset == "chapter":
        return (*start_pose(seed), 0.0, PUSHER_START_Y)
    if reset == "task":
        return task_start(seed)
    if reset in ("gym-pusht", "easy"):
        return tuple(float(v) for v in start_poses([seed], reset=reset)[0])
    raise ConfigError(f"unknown reset {reset!r}; choose from {', '.join(RESETS)}")


_BLOCK = 1 << 16  # seeds per block: the uint64 temporaries stay in cache


def start_poses(seeds: Sequence[int] | np.ndarray, *, reset: str = "chapter") -> np.ndarray:
    """(N, 3) float64 tee start poses for `chapter` ((N, 5) with the pusher's (x, y) for the others),
    row i exactly what seed i's own `default_rng` draws (`start_pose`, `task_start`, the `easy` draws in order).

    The generators are computed for all seeds at once (pcg64.Streams, well under 1 us a seed),
    not constructed one by one (~20 us a seed).
    """
    boundary.OneOf(tuple(RESETS))("reset", reset)  # an array is refused, not compared
    seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
    if reset == "gym-pusht":
        return gym_pusht_starts(seeds)
    out = np.empty((len(seeds), 3 if reset == "chapter" else 5))
    for lo in range(0, len(seeds), _BLOCK):
        out[lo : lo + _BLOCK] = _draw(seeds[lo : lo + _BLOCK], reset)
    return out


def _draw(seeds: np.ndarray, reset: str) -> np.ndarray:
    from mjx_pusht.task.pcg64 import Streams

    st = Streams(seeds)
    if reset == "chapter":
        return np.stack([st.uniform(*TEE_X_RANGE), st.uniform(*TEE_Y_RANGE), st.uniform(*TEE_YAW_RANGE)], axis=-1)
    if reset == "easy":
        dist, heading, yaw = st.uniform(*EASY_OFFSET), st.uniform(-np.pi, np.pi), st.uniform(-EASY_YAW, EASY_YAW)
        x, y, side = dist * np.cos(heading), dist * np.sin(heading), st.uniform(-np.pi, np.pi)
        return np.stack([x, y, yaw, x + EASY_PUSHER * np.cos(side), y + EASY_PUSHER * np.sin(side)], axis=-1)
    tee = np.stack([st.uniform(-TASK_TEE_HALF, TASK_TEE_HALF), st.uniform(-TASK_TEE_HALF, TASK_TEE_HALF),
                    st.uniform(-np.pi, np.pi)], axis=-1)
    pusher = np.empty((len(seeds), 2))
    todo = np.arange(len(seeds))
    for k in range(PUSHER_TRIES):  # try k for the rows whose earlier tries all landed on the T
        xy = np.stack([st.uniform(-TASK_PUSHER_HALF, TASK_PUSHER_HALF), st.uniform(-TASK_PUSHER_HALF, TASK_PUSHER_HALF)], -1)
        clear = (distance_to_tee(xy, tee[todo]) > PUSHER_RADIUS + CLEARANCE) | (k == PUSHER_TRIES - 1)
        pusher[todo[clear]] = xy[clear]
        todo = todo[~clear]
        if not len(todo):
            break
        st = st.subset(~clear)
    return np.concatenate([tee, pusher], axis=-1)


def gym_pusht_starts(seeds) -> np.ndarray:
    """(N, 5) starts of gym-pusht's reset, one generator per seed (about 20 us a seed: a drop-in's
    resets are few; the integer draws' bounded sampling is not in pcg64.Streams)."""
    from mjx_pusht.model.gym_pusht import legacy_state_to_world, reset_state

    seeds = np.asarray(seeds, np.int64).reshape(-1)
    if not len(seeds):
        return np.empty((0, 5))
    return legacy_state_to_world(np.stack([reset_state(int(s)) for s in seeds]))
