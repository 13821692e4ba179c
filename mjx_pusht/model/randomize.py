"""Physics randomised per episode: ranges of scale factors, each episode's draw from its seed, and the
per-world model fields a batch steps with.

    Scenario(..., randomize={"tee_mass": (0.5, 2.0), "kv": (0.8, 1.2)})   # CLI: --randomize tee_mass=0.5:2,kv=0.8:1.2

A range is of SCALE FACTORS on the task's own value (params.CURRENT of its compiled scene), as hydrax's
PushT draws friction x0.1..x2.0: the same range means the same thing on both tasks. Each episode draws
each factor uniformly from [lo, hi] (lo == hi fixes it: every episode at, say, a range's end) by a hash
of its seed and the parameter's name (`factors`): the same seed draws the same physics on every backend,
whatever else is randomised, and a draw costs no generator per seed (65,536 episodes at a reset).

What each name means (`MEANS`) depends on the task's scene; a name that means nothing there is refused in
one line (`REFUSED`). The draw's physics is the scene with those values set and MuJoCo's constants
re-derived (`params.apply`: mj_setConst), on MuJoCo C per row. On the batch each world's model is its
row's model with the drawn fields replaced, inside the one compiled program (`WorldFields`): every field
mj_setConst changes is a + b f + c / f in the factor f (mass, inertia, and their inverse weights),
fitted from three models MuJoCo derived and checked at two more, so a drawn world is the model MuJoCo
would derive for it, to float rounding (tests/test_randomize.py steps one against MuJoCo C).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mjx_pusht.model.params import BOUNDS, CURRENT, PARAMS, REFUSED, ParamError, apply, means_nothing

MEANS = {
    "chapter": {
        "kv": "the pusher's velocity-servo gain (20)",
        "tee_mass": "the block's mass and rotational inertia together (0.105 kg)",
        "tee_damping": "the block's viscous drag on the table, its x/y joint damping (4)",
        "tee_frictionloss": "the block's dry friction on the table, its x/y joint frictionloss (1.2)",
    },
    "gym-pusht": {
        "kp": "the agent's PD position gain, gym-pusht's KP (100 x the agent's mass)",
        "kv": "the agent's PD velocity gain, gym-pusht's KV (20 x the agent's mass)",
    },
}
# Fields mj_setConst changes that nothing MJX steps reads: cam_poscom0 only cameras that track a centre of mass
# (every camera here is fixed: checked in WorldFields), dof_M0 nothing in MJX or MuJoCo Warp
UNREAD = ("cam_poscom0", "dof_M0")
_PROBES, _CHECKS = (1.0, 2.0, 4.0), (0.5, 3.0)


def check(randomize, scene, where: str = "randomize") -> tuple[tuple[str, tuple[float, float]], ...]:
    """(name, (lo, hi)) pairs in PARAMS order: known names that mean something on `scene`'s task (a SceneSpec),
    finite factors lo <= hi whose values (factor x the scene's own) stay within params.BOUNDS."""
    try:  # a 0-d array has a __len__ that raises; a name that is not a string cannot be looked up
        if randomize is None or not len(randomize):
            return ()
        pairs = list(randomize.items() if isinstance(randomize, dict) else randomize)
        pairs = [(name, tuple(r)) for name, r in pairs]
        if not all(isinstance(name, str) for name, _ in pairs):
            raise TypeError(randomize)
    except (TypeError, ValueError):
        raise ParamError(f"{where} must map names to (lo, hi) scale factors, got {randomize!r}") from None
    if len({n for n, _ in pairs}) != len(pairs):
        raise ParamError(f"{where}: each parameter may be given once")
    from mjx_pusht.model.scene import build_model

    variant, model, out = scene.variant, build_model(scene), {}
    for name, r in pairs:
        means_nothing(name, variant, where)
        if name not in MEANS.get(variant, {}):
            raise ParamError(f"{where}: unknown parameter {name!r}; on the {variant} task choose from "
                             f"{', '.join(MEANS.get(variant, {}))}")
        if len(r) != 2 or not all(isinstance(x, (int, float, np.number)) and not isinstance(x, bool) for x in r):
            raise ParamError(f"{where}: {name}'s range must be two numbers (lo, hi), got {r!r}")
        lo, hi = float(r[0]), float(r[1])
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ParamError(f"{where}: {name}'s range must be finite, got {r!r}")
        if lo > hi:
            raise ParamError(f"{where}: {name}'s range is inverted ({lo:g} > {hi:g}); give lo <= hi")
        base, (b_lo, b_hi, lo_open) = CURRENT[name](model), BOUNDS[name]
        for f in (lo, hi):
            v = f * base
            if not ((b_lo < v if lo_open else b_lo <= v) and v <= b_hi):
                raise ParamError(f"{where}: {name} x{f:g} is {v:g}, outside where it means what its name says "
                                 f"({'(' if lo_open else '['}{b_lo:g}, {b_hi:g}]; the task's own: {base:g})")
        out[name] = (lo, hi)
    return tuple((n, out[n]) for n in PARAMS if n in out)


def parse(text: str) -> dict[str, tuple[float, float]]:
    """The CLI's `--randomize NAME=lo:hi,NAME=lo:hi` (scale factors) as check() takes it."""
    out: dict[str, tuple[float, float]] = {}
    for part in text.split(","):
        name, sep, span = part.strip().partition("=")
        bounds = span.split(":")
        if name.strip() in out:
            raise ParamError(f"--randomize {text!r}: each parameter may be given once")
        try:
            if not sep or len(bounds) != 2:
                raise ValueError
            out[name.strip()] = (float(bounds[0]), float(bounds[1]))
        except ValueError:
            raise ParamError(f"--randomize {text!r}: expected NAME=lo:hi[,NAME=lo:hi] (scale factors on the "
                             "task's own values, e.g. tee_mass=0.5:2)") from None
    return out


def _unit(seeds: np.ndarray, name: str) -> np.ndarray:
    """A uniform number in [0, 1) per seed: splitmix64 of the seed and the name (53 bits, exact in float64)."""
    salt = np.uint64(int.from_bytes(name.encode()[:8].ljust(8, b"\0"), "little"))
    with np.errstate(over="ignore"):
        z = np.asarray(seeds, np.uint64) * np.uint64(0x9E3779B97F4A7C15) + salt
        for shift, mul in ((30, 0xBF58476D1CE4E5B9), (27, 0x94D049BB133111EB)):
            z = (z ^ (z >> np.uint64(shift))) * np.uint64(mul)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * 2.0**-53


def factors(randomize, seeds) -> np.ndarray:
    """(N, k) scale factors, one row per seed, one column per randomised parameter (check()'s order)."""
    seeds = np.asarray(seeds, np.int64)
    cols = [lo + _unit(seeds, name) * (hi - lo) for name, (lo, hi) in randomize]
    return np.stack(cols, axis=1) if cols else np.zeros((len(seeds), 0))


def values(model: mujoco.MjModel, randomize, f: np.ndarray) -> dict[str, np.ndarray]:
    """The drawn physics as the parameters' own values (kg, gains): factor x the scene's own, per row."""
    return {name: f[:, j] * CURRENT[name](model) for j, (name, _) in enumerate(randomize)}


def row_models(model: mujoco.MjModel, randomize, f: np.ndarray) -> list[mujoco.MjModel]:
    """MuJoCo C's model of each row: the scene with its row's values set and its constants re-derived."""
    v = values(model, randomize, f)
    return [apply(model, {name: v[name][i] for name in v}) for i in range(len(f))]


class WorldFields:
    """Each world's drawn fields on the batch: field = a + b f + c / f per element that the factor f moves.

    The coefficients are fitted, per parameter, from `params.apply` (MuJoCo's own mj_setConst) at three
    factors and checked at two more; a field that does not follow that form, or that two parameters both
    move, is a bug here and raises. Host NumPy; `world` runs inside the batch's program."""

    def __init__(self, model: mujoco.MjModel, randomize):
        self.fields: dict[str, list] = {}  # field -> [(column j, flat indices, a, b, c)]
        if not randomize:
            return
        if (model.cam_mode != mujoco.mjtCamLight.mjCAMLIGHT_FIXED).any():
            raise RuntimeError("a camera tracks a centre of mass: cam_poscom0 would vary per world")
        moved: dict[str, np.ndarray] = {}
        for j, (name, _) in enumerate(randomize):
            base = CURRENT[name](model)
            probes = [apply(model, {name: f * base}) for f in _PROBES + _CHECKS]
            for field in _float_fields(model):
                ys = np.stack([np.asarray(getattr(p, field), np.float64).ravel() for p in probes])
                idx = np.flatnonzero((ys != ys[0]).any(axis=0))
                if not len(idx) or field in UNREAD:
                    continue
                if np.isin(idx, moved.get(field, [])).any():
                    raise RuntimeError(f"{field}: moved by two randomised parameters")
                moved[field] = np.concatenate([moved.get(field, np.zeros(0, int)), idx])
                basis = lambda fs: np.stack([np.ones_like(fs), fs, 1.0 / fs], axis=1)  # noqa: E731
                coef = np.linalg.solve(basis(np.array(_PROBES)), ys[:3, idx])
                # a term the field does not have is exactly 0 (its solve leaves rounding): a factor 0 of a gain
                # is then 0, not 0 / 0
                coef[np.abs(coef) <= 1e-12 * np.abs(ys[:, idx]).max(axis=0)] = 0.0
                fit = basis(np.array(_CHECKS)) @ coef
                if not np.allclose(fit, ys[3:, idx], rtol=1e-9, atol=0):
                    raise RuntimeError(f"{field} is not a + b f + c / f in {name}'s factor")
                self.fields.setdefault(field, []).append((j, idx, *coef))

    def world(self, mx, f):
        """`mx` (one world's mjx.Model) with the fields of factors `f` (k,): traced, under vmap a field per world."""
        import jax.numpy as jnp

        out = {}
        for field, parts in self.fields.items():
            x = getattr(mx, field)
            flat = x.reshape(-1)
            for j, idx, a, b, c in parts:
                fj = f[j].astype(x.dtype)
                v = jnp.asarray(a, x.dtype) + jnp.asarray(b, x.dtype) * fj
                if c.any():
                    v = v + jnp.asarray(c, x.dtype) / fj
                flat = flat.at[idx].set(v)
            out[field] = flat.reshape(x.shape)
        return mx.replace(**out) if out else mx


def _float_fields(model: mujoco.MjModel) -> list[str]:
    return [f for f in dir(model) if not f.startswith("_") and isinstance(getattr(model, f, None), np.ndarray)
            and getattr(model, f).dtype.kind == "f"]
