"""The public entries' own checks: the helpers `import mjx_pusht` exports, each argument through the boundary's declared rules (boundary.py):
seeds are integers from 0 to 2**63-1 (never None, a float or a string), scenes a `SceneSpec`, models a compiled
`mujoco.MjModel`, positions finite real arrays of matching shape. A bad argument is one `ConfigError` line where
NumPy's or MuJoCo's traceback came (`start_pose(-1)`, `build_model(None)`, `weld_gap(np.zeros(2), np.zeros(3))`).

`keywords`: a constructor refusing a keyword it does not take in one line; `run_options`: `Backend.run`'s options.
The package's own code calls the unchecked functions (task/, model/): inside a jitted step the invariants take
traced arrays, which no NumPy check may touch, and their inputs passed the door already."""

from __future__ import annotations

import functools

import numpy as np

from mjx_pusht import boundary, validate
from mjx_pusht.errors import ConfigError
from mjx_pusht.model import scene as _scene
from mjx_pusht.model import tree as _tree
from mjx_pusht.task import invariants as _inv
from mjx_pusht.task import reset as _reset

_SPEC = boundary.Instance("mjx_pusht.model.scene:SceneSpec", "a SceneSpec (SceneSpec('none'), ...)")
_MODEL = boundary.Instance("mujoco:MjModel", "a compiled mujoco.MjModel (build_model(SceneSpec()))")


def _seed(name, value, error=ConfigError) -> int:
    if value is None:  # NumPy draws fresh OS entropy for None: a different pose each call
        raise error(f"{name} must be an integer from 0 to 2**63-1, got None")
    return validate.seed(value, name)


def _positions(*names):
    """Real finite arrays with 3 in their last axis, of one shape (a (3,) pair or (N, 3) rows)."""
    def rule(values):
        arrays = [boundary.Array((-1,) * max(np.ndim(v), 1))(n, v) for n, v in zip(names, values)]
        if arrays[0].shape[-1:] != (3,) or any(a.shape != arrays[0].shape for a in arrays):
            raise ConfigError(f"{' and '.join(names)} must be positions of one shape (..., 3), got "
                              f"{' and '.join(str(a.shape) for a in arrays)}")
        return arrays
    return rule


@functools.lru_cache(maxsize=None)
def _signature(function):
    """`function`'s signature, made once (a policy's __call__ binds its argument every step)."""
    import inspect

    return inspect.signature(function)


def _bind(function, args, kwargs, where: str | None = None):
    """Python's own check of a call's arguments (a missing one, one given twice, a keyword not taken), as one
    `KeywordError` line naming the arguments `function` takes; returns the arguments as positional and keyword."""
    signature = _signature(function)
    try:
        bound = signature.bind(*args, **kwargs)
    except TypeError as e:
        takes = [n for n, p in signature.parameters.items() if n not in ("self", "cls") and p.kind != p.VAR_KEYWORD]
        # in Python's own words ("X() got an unexpected keyword argument 'y'": torchrl's GymEnv retries on them)
        raise KeywordError(f"{where or function.__qualname__ + '()'} {e}; it takes {', '.join(takes) or 'no arguments'}") from None
    return bound.args, bound.kwargs


def _checked(function, *rules, **keyword_rules):
    """`function` with its arguments bound (`_bind`), the first ones through `rules` (one each, in order) and its
    keyword-only ones through `keyword_rules` (by name)."""
    @functools.wraps(function)
    def call(*args, **kwargs):
        args, kwargs = _bind(function, args, kwargs)
        kwargs = {k: keyword_rules[k](k, v) if k in keyword_rules else v for k, v in kwargs.items()}
        return function(*(rule(v) for rule, v in zip(rules, args)), *args[len(rules):], **kwargs)
    return call


start_pose = _checked(_reset.start_pose, lambda v: _seed("seed", v))
start_poses = _checked(_reset.start_poses, validate.seed_array)
build_model = _checked(_scene.build_model, lambda v: _SPEC("spec", v), validate=boundary.Flag())  # "no" was True
scene_xml = _checked(_scene.scene_xml, lambda v: _SPEC("spec", v))
read_tree = _checked(_tree.read_tree, lambda v: _MODEL("model", v))
check_tree = _checked(_tree.check_tree, lambda v: _MODEL("model", v),
                      lambda v: boundary.OneOf(tuple(_tree.EXPECTED_TREES))("break_it", v))
stayed_rigid = _checked(_inv.stayed_rigid, lambda v: boundary.Array((-1,) * np.ndim(v), finite=False)("gap_max_dev", v))


def _pair(function):
    @functools.wraps(function)
    def call(*args, **kwargs):
        args, _ = _bind(function, args, kwargs)  # both are positional-or-keyword: bound, they are positional
        return function(*_positions("bar_pos", "stem_pos")(args))
    return call


weld_gap = _pair(_inv.weld_gap)
gap_deviation = _pair(_inv.gap_deviation)


class KeywordError(ConfigError, TypeError):
    """A keyword an entry does not take (a TypeError, as Python's own, in one line naming those it takes)."""


def keywords(function):
    """A constructor or function refusing a keyword it does not take, a missing argument or one given twice, in one
    line naming those it takes (Python's TypeError named only the stranger, with a traceback: `gym.make(ID,
    bogus=1)`). A function taking **kwargs checks those itself."""
    @functools.wraps(function)
    def checked(*args, **kwargs):
        _bind(function, args, kwargs)
        return function(*args, **kwargs)
    return checked


def keyword_checked(cls):
    """`cls` with `__init__` and every public method of its own through `keywords` (a method left out was the next
    hostile pass's finding: `AutoReset.refill(state, bogus=1)`, the tenth)."""
    import inspect

    for name, f in list(vars(cls).items()):
        if (name == "__init__" or not name.startswith("_")) and inspect.isfunction(f) and not hasattr(f, "__wrapped__"):
            setattr(cls, name, keywords(f))
    return cls


def run_options(scenario, seeds, batch, combos, poses):
    """`Backend.run`'s arguments: seeds (and their memory), `batch` a positive count, `combos` one parameter
    combination index per seed (0 .. len(scenario.grid()) - 1), `poses` one finite start per seed ((x, y, yaw), and
    (px, py) after it where the starts place the pusher)
    (a NaN start was stepped into MuJoCo, which wrote MUJOCO_LOG.TXT into the caller's folder). Returns the seeds,
    combos and poses as arrays (None where not given)."""
    seeds = validate.seed_array(seeds)
    boundary.fits(f"{len(seeds):,} seeds", len(seeds), boundary.BYTES_PER_SEED, "fewer seeds a run")
    boundary.Maybe(boundary.Int(1, boundary.MAX_ENVS))("batch", batch)
    if combos is not None:
        combos = boundary.Array((len(seeds),), kinds="iu")("combos", np.atleast_1d(combos))
        n = len(scenario.grid())
        if combos.size and (combos.min() < 0 or combos.max() >= n):
            raise ConfigError(f"combos must index the scenario's {n} parameter combinations (0..{n - 1}), got "
                              f"{boundary._show(combos.tolist())}")
    if poses is not None:  # the tee's (x, y, yaw) on the chapter's starts, and the pusher's (x, y) after it elsewhere
        poses = boundary.Array((len(seeds), 3 if scenario.reset == "chapter" else 5))("poses", poses)
    return seeds, combos, poses
