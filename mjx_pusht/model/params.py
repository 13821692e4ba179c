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

from mjx_pusht import validate
from mjx_pusht.errors import ConfigError, MjxPushtError


def _tee_dofs(m: mujoco.MjModel) -> list[int]:
    return [int(m.joint(n).dofadr[0]) for n in ("tee_x", "tee_y")]


def _velocity_servos(m: mujoco.MjModel) -> bool:
    # a velocity servo has no position term (bias -kp on qpos); gym-pusht's position servos do
    return not m.actuator_biasprm[:, 1].any()


def _kv(m: mujoco.MjModel, v: float) -> None:
    # a velocity servo is gain kv on ctrl and bias -kv on joint velocity; a position servo's kv is its bias alone
    if _velocity_servos(m):
        m.actuator_gainprm[:, 0] = v
    m.actuator_biasprm[:, 2] = -v


def _kp(m: mujoco.MjModel, v: float) -> None:
    # a position servo is gain kp on ctrl (the target) and bias -kp on the joint's position
    if _velocity_servos(m):
        raise ParamError("kp: this scene's pusher is on velocity servos, which have no position gain (use kv)")
    m.actuator_gainprm[:, 0] = v
    m.actuator_biasprm[:, 1] = -v


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


def _tee_mass_of(m: mujoco.MjModel) -> float:
    return float(sum(m.body_mass[i] for i in range(m.nbody) if m.body(i).name in ("tee", "tee_stem_body")))


PARAMS: dict[str, tuple[Callable[[mujoco.MjModel, float], None], str]] = {
    "kv": (_kv, "pusher servo velocity gain (chapter: 20; gym-pusht: its PD law's KV x the agent's mass, 2e7)"),
    "kp": (_kp, "pusher position-servo gain (gym-pusht's only: its PD law's KP x the agent's mass, 1e8)"),
    "tee_damping": (_tee_damping, "tee x/y joint damping (chapter: 4)"),
    "tee_frictionloss": (_tee_frictionloss, "tee x/y joint frictionloss (chapter: 1.2)"),
    "tee_mass": (_tee_mass, "tee total mass in kg (chapter: 0.105)"),
}

# each parameter's value in a model (the scene's own, before any edit): what randomize.py's scale factors multiply
CURRENT: dict[str, Callable[[mujoco.MjModel], float]] = {
    "kv": lambda m: float(-m.actuator_biasprm[0, 2]),
    "kp": lambda m: float(-m.actuator_biasprm[0, 1]),
    "tee_damping": lambda m: float(m.dof_damping[_tee_dofs(m)[0]]),
    "tee_frictionloss": lambda m: float(m.dof_frictionloss[_tee_dofs(m)[0]]),
    "tee_mass": _tee_mass_of,
}

MAX_VAL = 1e10  # MuJoCo's mjMAXVAL: a number past it is, to MuJoCo, a diverged state
# (low, high, low excluded): where each parameter means what its name says. Measured with the chapter's nudge on
# 8 seeds of MuJoCo C (docs/notebook/h-apierr.md), where the physics stops meaning it:
# - kv: a velocity servo's gain. 0 is a servo switched off (the pusher stays: a dull but true study); a negative
#   gain drives the pusher away from its target (kv=-1 moved it 12 cm south against a northward nudge, every
#   flag clean). Up to mjMAXVAL the implicit integrator keeps it stable (1e10 pushes the T as 20 does).
# - tee_damping, tee_frictionloss: dissipation, never negative. Negative damping feeds energy in (-5 diverged);
#   a negative frictionloss pushes the T (-5 slid it against the push). Capped at mjMAXVAL.
# - tee_mass: MuJoCo's soft contacts are regularised by the effective mass of the bodies they touch, so a T far
#   lighter or heavier than the 0.2 kg pusher lets the pusher through it: at 3 g and at 1e9 kg the pusher
#   travelled as far as with no T in its way (62.6 and 30 cm against 23 cm for 1e3 to 1e8 kg, which stop it),
#   and 1e300 kg left it outside the south wall. Between 10 g and 1e8 kg the pusher moves the T or is stopped.
BOUNDS: dict[str, tuple[float, float, bool]] = {
    "kv": (0.0, MAX_VAL, False),
    "kp": (0.0, MAX_VAL, True),  # a position servo's stiffness: 0 is no servo; negative drives it away
    "tee_damping": (0.0, MAX_VAL, False),
    "tee_frictionloss": (0.0, MAX_VAL, False),
    "tee_mass": (1e-2, 1e8, False),
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
    return name, check_values(name, out, f"--param {text!r}")


def check_values(name: str, values, where: str) -> list[float]:
    """A parameter's values: a non-empty list of real numbers within its BOUNDS (the CLI's and the API's check)."""
    if not isinstance(name, str) or name not in PARAMS:  # an array as a name: not compared element by element
        raise ParamError(f"{where}: unknown parameter {name!r}; choose from {', '.join(PARAMS)}")
    if isinstance(values, (str, bytes)) or not hasattr(values, "__len__") or not len(values):
        raise ParamError(f"{where}: {name}'s values must be a non-empty sequence of numbers, got {values!r}")
    lo, hi, lo_open = BOUNDS[name]
    try:
        return [validate.real_range(name, v, lo, hi, lo_open) for v in values]
    except ConfigError as e:
        raise ParamError(f"{where}: {e}") from None


def check_params(params, where: str = "params") -> tuple[tuple[str, tuple[float, ...]], ...]:
    """(name, values) pairs: each a known NAME once, its values within bounds, the grid at most MAX_COMBINATIONS
    combinations. Returned as tuples of floats."""
    if isinstance(params, (str, bytes, dict)) or not hasattr(params, "__iter__") or (
            isinstance(params, np.ndarray) and params.ndim == 0):
        raise ParamError(f"{where} must be (name, values) pairs, got {params!r}")
    out = []
    for pair in params:
        if isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2:
            raise ParamError(f"{where} must be (name, values) pairs, got {pair!r}")
        name, values = pair
        out.append((name, tuple(check_values(name, values, where))))
    if len({n for n, _ in out}) != len(out):
        raise ParamError(f"{where}: each parameter NAME may be given once")
    combos = int(np.prod([len(v) for _, v in out]))
    if combos > MAX_COMBINATIONS:
        raise ParamError(f"{where}: a grid of {combos:,} combinations; at most {MAX_COMBINATIONS:,} (each is its own "
                         "model): sweep fewer values, or split the study")
    return tuple(out)


def parse_params(texts) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """Every `--param` of a command: each NAME once, the grid at most MAX_COMBINATIONS combinations."""
    return check_params([parse_param(t) for t in texts], "--param")


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


# The parameters that mean nothing on a task, and why: refused by --param (a grid) and --randomize (per episode)
# alike, through `means_nothing`
REFUSED = {
    ("chapter", "kp"): "the chapter's pusher is on velocity servos, which have no position gain (kv is their gain)",
    ("gym-pusht", "tee_mass"): "gym-pusht's agent is kinematic and its block keeps no velocity between steps, so "
                               "the block's mass changes nothing there (as in pymunk)",
    ("gym-pusht", "tee_damping"): "gym-pusht's block damping is pymunk's velocity reset (mass / dt), not a "
                                  "table's drag: changing it changes gym-pusht's rule, not its physics",
    ("gym-pusht", "tee_frictionloss"): "gym-pusht's block slides without friction (pymunk reads none): there is "
                                       "no friction to scale",
}


def means_nothing(name: str, variant: str, where: str) -> None:
    """Refuse `name` where it means nothing on the `variant` task (REFUSED says why)."""
    if (variant, name) in REFUSED:
        raise ParamError(f"{where}: {name} means nothing on the {variant} task: {REFUSED[variant, name]}")


def check_scene(model: mujoco.MjModel, params) -> None:
    """Each parameter's values set on the scene's model once, so that one that means nothing on this scene (kp on
    velocity servos) is refused before a run claims its folder, not when its backend builds the model."""
    for name, values in params:
        for v in values:
            apply(model, {name: v})


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
