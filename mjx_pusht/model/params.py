"""Physical parameters by name, applied to a compiled model, and grids of them for sweeps.

Each parameter edits the CPU MjModel and then re-derives MuJoCo's constants
(mj_setConst), so a parameterised model is exactly what compiling the edited
scene would give; MJX backends stack the fields that differ across the grid and
batch over them, so a grid is one compiled program, not one per value.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import mujoco
import numpy as np

from mjx_pusht.errors import MjxPushtError


def _tee_dofs(m: mujoco.MjModel) -> list[int]:
    return [int(m.joint(n).dofadr[0]) for n in ("tee_x", "tee_y")]


def _kv(m: mujoco.MjModel, v: float) -> None:
    # a velocity servo is gain kv on ctrl and bias -kv on joint velocity
    m.actuator_gainprm[:, 0] = v
    m.actuator_biasprm[:, 2] = -v


def _tee_damping(m: mujoco.MjModel, v: float) -> None:
    m.dof_damping[_tee_dofs(m)] = v


def _tee_frictionloss(m: mujoco.MjModel, v: float) -> None:
    m.dof_frictionloss[_tee_dofs(m)] = v


def _tee_mass(m: mujoco.MjModel, v: float) -> None:
    # scale the whole tee (bar and stem bodies alike) so its total mass is v, inertia with it
    bodies = [i for i in range(m.nbody) if m.body(i).name in ("tee", "tee_stem_body")]
    total = float(m.body_mass[bodies].sum())
    for b in bodies:
        m.body_mass[b] *= v / total
        m.body_inertia[b] *= v / total


PARAMS: dict[str, tuple[Callable[[mujoco.MjModel, float], None], str]] = {
    "kv": (_kv, "pusher velocity-servo gain (chapter: 20)"),
    "tee_damping": (_tee_damping, "tee x/y joint damping (chapter: 4)"),
    "tee_frictionloss": (_tee_frictionloss, "tee x/y joint frictionloss (chapter: 1.2)"),
    "tee_mass": (_tee_mass, "tee total mass in kg (chapter: 0.105)"),
}


class ParamError(MjxPushtError, ValueError):
    pass


DRAW_SEED = 0  # random draws from a range come from this fixed generator, so a sweep is repeatable
# Each combination of a grid is its own MjModel (and its own rows of every seed): a grid past this many is a
# typo (lo:hi:100000000 was a MemoryError), refused before any array is made
MAX_COMBINATIONS = 4096


def parse_param(text: str) -> tuple[str, list[float]]:
    """`NAME=a,b,c` (listed), `NAME=lo:hi:n` (n evenly spaced, ends included) or `NAME=~lo:hi:n`
    (n uniform random draws from [lo, hi), from a generator seeded with DRAW_SEED and the name)."""
    name, sep, values = text.partition("=")
    name = name.strip()
    if not sep or name not in PARAMS:
        raise ParamError(f"--param {text!r}: expected NAME=VALUES with NAME one of {', '.join(PARAMS)}")
    try:
        if values.startswith("~"):
            lo, hi, n = values[1:].split(":")
            if not 1 <= int(n) <= MAX_COMBINATIONS or not float(lo) < float(hi):
                raise ValueError
            rng = np.random.default_rng([DRAW_SEED, *name.encode()])
            out = [float(v) for v in rng.uniform(float(lo), float(hi), int(n))]
        elif ":" in values:
            lo, hi, n = values.split(":")
            if not 1 <= int(n) <= MAX_COMBINATIONS:
                raise ValueError
            out = list(np.linspace(float(lo), float(hi), int(n)))
        else:
            out = [float(v) for v in values.split(",")]
    except ValueError:
        raise ParamError(f"--param {text!r}: values are a,b,c, lo:hi:n or ~lo:hi:n (n from 1 to "
                         f"{MAX_COMBINATIONS})") from None
    if not out or not all(np.isfinite(out)) or min(out) < 0 or (name == "tee_mass" and min(out) <= 0):
        raise ParamError(f"--param {text!r}: values must be finite and non-negative (mass positive)")
    return name, out


def parse_params(texts) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """Every `--param` of a command: each NAME once, the grid at most MAX_COMBINATIONS combinations."""
    params = tuple((n, tuple(v)) for n, v in (parse_param(t) for t in texts))
    if len({n for n, _ in params}) != len(params):
        raise ParamError("each --param NAME may be given once")
    combos = int(np.prod([len(v) for _, v in params]))
    if combos > MAX_COMBINATIONS:
        raise ParamError(f"--param: a grid of {combos:,} combinations; at most {MAX_COMBINATIONS:,} (each is its own "
                         "model): sweep fewer values, or split the study")
    return params


def grid(params: dict[str, list[float]]) -> list[dict[str, float]]:
    """Every combination of the listed values (one empty combination when no parameter is given)."""
    names = list(params)
    return [dict(zip(names, combo)) for combo in itertools.product(*(params[n] for n in names))]


def apply(model: mujoco.MjModel, values: dict[str, float]) -> mujoco.MjModel:
    """A copy of `model` with the parameters set and MuJoCo's derived constants recomputed."""
    import copy

    m = copy.copy(model)
    for name, v in values.items():
        PARAMS[name][0](m, float(v))
    mujoco.mj_setConst(m, mujoco.MjData(m))
    return m


def warning_bits(data: mujoco.MjData) -> int:
    """The MuJoCo warnings `data` has raised since it was made, as a bitmask of 1 << mjtWarning."""
    return sum(1 << i for i, n in enumerate(data.warning.number) if n > 0)


def warning_names(bits: int) -> list[str]:
    """mjWARN_INERTIA-style names of a warning bitmask, for summaries and messages."""
    return [mujoco.mjtWarning(i).name for i in range(int(mujoco.mjtWarning.mjNWARNING)) if bits >> i & 1]


def model_warnings(model: mujoco.MjModel) -> int:
    """The warnings MuJoCo raises on this model before anything moves (mj_forward at its rest pose).

    A parameter can make a model MuJoCo cannot trust: a tee of 1e-300 kg gives a singular inertia
    matrix, MuJoCo prints a warning and carries on, the pusher never moves and every row would
    read finite and rigid. Every backend compiles from this model, so this check covers MJX too
    (which raises no warnings of its own)."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return warning_bits(data)
