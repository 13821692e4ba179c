"""The boundary's rules, declared: what each public entry takes, as tables of rules rather than an `if` per case.

A rule is a small value (`Int(1, 4096)`, `OneOf(...)`, `Array((5,))`, `Address()`) that checks one input and
returns it normalised, or raises the package's one-line error naming the input and the value. A table maps an
entry's names to rules; `check` refuses a name the table does not hold (a keyword that would be ignored is
refused, never ignored) and applies the rest. Combinations of inputs that cannot be honoured together are
declared beside the tables (`COMBINATIONS`) and refused by `refuse_combinations`.

The entries here are the ones whose checks were missing or scattered: the multi-process flags (`Processes`),
`make_backend`'s keyword options, the functional env's constructor, a vector env's `set_attr`, the package's
own reset options, and a gym-pusht policy's observation. validate.py holds the env's per-call checks (seeds,
actions, starts), which these rules call where they share a meaning.

Checks run at the door (construction, reset, a command's start), never once a step: a step pays for no check
its inputs already passed.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import numbers
import os
import re

import numpy as np

from mjx_pusht.errors import ConfigError, MjxPushtError


def _show(value, limit: int = 60) -> str:
    """`value` for a one-line message: its repr on one line (an array's rows joined), cut to `limit`."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclasses.dataclass(frozen=True)
class Int:
    """An integer in [low, high] (never a bool, a float or a string: those are refused, not truncated)."""

    low: int
    high: int | None = None

    def __call__(self, name, value, error=ConfigError) -> int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < self.low or (
                self.high is not None and value > self.high):
            span = f"from {self.low:,}" + (f" to {self.high:,}" if self.high is not None else "")
            raise error(f"{name} must be an integer {span}, got {_show(value)}")
        return int(value)


@dataclasses.dataclass(frozen=True)
class Real:
    """A finite real number in [low, high] ((low, high] where `low_open`): never NaN, inf, a bool or complex."""

    low: float
    high: float
    low_open: bool = False

    def __call__(self, name, value, error=ConfigError) -> float:
        ok = not isinstance(value, bool) and isinstance(value, numbers.Real) and (
            (self.low < value) if self.low_open else (self.low <= value)) and value <= self.high
        if not ok:
            span = f"{'(' if self.low_open else '['}{self.low:g}, {self.high:g}]"
            raise error(f"{name} must be a finite number in {span}, got {_show(value)}")
        return float(value)


@dataclasses.dataclass(frozen=True)
class Flag:
    """True or False (not 0, 1 or a string: `"False"` is truthy)."""

    def __call__(self, name, value, error=ConfigError) -> bool:
        if not isinstance(value, (bool, np.bool_)):
            raise error(f"{name} must be True or False, got {_show(value)}")
        return bool(value)


@dataclasses.dataclass(frozen=True)
class OneOf:
    """One of the named `options`, compared as values of their type (an array or a list is refused, never compared
    element by element)."""

    options: tuple | str  # or "module:NAME", a tuple imported when first checked (no import cycle at load)

    def __call__(self, name, value, error=ConfigError):
        options = self.options
        if isinstance(options, str):
            import importlib

            module, attr = options.split(":")
            options = tuple(getattr(importlib.import_module(module), attr))
        if not any(isinstance(value, type(o)) and value == o for o in options):
            raise error(f"unknown {name} {_show(value)}; choose from {', '.join(map(str, options))}")
        return value


@dataclasses.dataclass(frozen=True)
class Instance:
    """An instance of `kind` (a class, or a dotted 'module:Class' imported when first checked)."""

    kind: object
    what: str

    def __call__(self, name, value, error=ConfigError):
        kind = self.kind
        if isinstance(kind, str):
            import importlib

            module, cls = kind.split(":")
            kind = getattr(importlib.import_module(module), cls)
        if not isinstance(value, kind):
            raise error(f"{name} must be {self.what}, got {_show(value)}")
        return value


@dataclasses.dataclass(frozen=True)
class Maybe:
    """None, or what `rule` takes."""

    rule: object

    def __call__(self, name, value, error=ConfigError):
        return None if value is None else self.rule(name, value, error)


@dataclasses.dataclass(frozen=True)
class Address:
    """HOST:PORT: a host name or an IP address (IPv6 in brackets), and a port from 1 to 65535. Checked before any
    network use: a port past 65535 was an OverflowError from bind(), a host with a space a hang."""

    HOST = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}"
                      r"[A-Za-z0-9])?)*\.?$")

    def __call__(self, name, value, error=ConfigError) -> str:
        if not isinstance(value, str) or ":" not in value:
            raise error(f"{name} must be HOST:PORT, got {_show(value)}")
        host, port = value.rsplit(":", 1)
        if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
            raise error(f"{name} {value!r}: the port must be an integer from 1 to 65535, got {port!r}")
        bare = host[1:-1] if host.startswith("[") and host.endswith("]") else host
        try:
            ipaddress.ip_address(bare)
        except ValueError:
            if bare != host or not self.HOST.match(host):
                raise error(f"{name} {value!r}: {host!r} is not a host name or an IP address") from None
        return value


@dataclasses.dataclass(frozen=True)
class Array:
    """An array of real numbers (never bools, complex, strings or objects: each was cast silently before) whose
    shape is `shape` (-1: any length there), finite unless `finite` is False."""

    shape: tuple
    kinds: str = "fiu"
    finite: bool = True

    def __call__(self, name, value, error=ConfigError) -> np.ndarray:
        try:
            a = np.asarray(value)
        except (ValueError, TypeError):  # ragged lists
            raise error(f"{name} must be an array of shape {_dims(self.shape)}, got {_show(value)}") from None
        if a.dtype.kind not in self.kinds:  # named by the kinds asked for (float images were "not real numbers")
            what = {"fiu": "real numbers", "iu": "integers", "u": "unsigned integers (uint8 for an image)"}.get(
                self.kinds, "real numbers")
            raise error(f"{name} must be {what}, got {a.dtype} ({_show(value)})")
        if a.ndim != len(self.shape) or any(w not in (-1, d) for w, d in zip(self.shape, a.shape)):
            raise error(f"{name} must have shape {_dims(self.shape)}, got {a.shape}")
        if self.finite and a.dtype.kind == "f" and not np.isfinite(a).all():
            raise error(f"{name} must be finite numbers, got {_show(a.tolist())}")
        return a


def _dims(shape) -> str:
    return "(" + ", ".join("N" if d == -1 else str(d) for d in shape) + ("," if len(shape) == 1 else "") + ")"


def check(table: dict, values: dict, where: str, error=ConfigError) -> dict:
    """Every name of `values` through its rule in `table`; a name the table does not hold is refused (naming
    those it does), never ignored."""
    unknown = sorted(set(values) - set(table), key=str)
    if unknown:
        takes = ", ".join(table) if table else "no options"
        raise error(f"{where} takes no {', '.join(map(repr, unknown))}; it takes {takes}")
    return {k: table[k](k, v, error) for k, v in values.items()}


def refuse_combinations(rules: tuple, values: dict, error=ConfigError) -> None:
    """The first of `rules` ((refused(values) -> bool, message)) that holds for `values` is raised (`message`: a
    format string of the values, or a function of them)."""
    for refused, message in rules:
        if refused(values):
            raise error(message(values) if callable(message) else message.format(**values))


def available_memory() -> int | None:
    """The bytes this machine can still give a process (psutil's `available`, else /proc/meminfo's MemAvailable,
    else free pages by os.sysconf), or None where none of them says."""
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except ImportError:
        pass
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def _size(n: float) -> str:
    return f"{n / 2**30:,.1f} GiB" if n >= 2**30 else f"{n / 2**20:,.0f} MiB"


def fits(what: str, count: int, per: int, hint: str, error=ConfigError, measured: bool = True) -> None:
    """Refuse, before any work or file, `count` items of about `per` bytes each (`what`: the input that asks for
    them) where they would not fit in the memory this machine has available now: such a run grew until the
    kernel killed it (19 GB in 26 s, then the whole machine's OOM killer), where a line and an exit were due."""
    need = count * per
    have = available_memory()
    if have is not None and need > have:
        raise error(f"{what} needs about {_size(need)} of memory ({_size(per) if per >= 2**20 else f'{per:,} bytes'}"
                    f" each, {'measured' if measured else 'from the sizes'}), more than the {_size(have)} this machine "
                    f"has available: {hint}")


def jax_cache(path=None):
    """The folder of XLA's compile cache (`path`, else $MJX_PUSHT_JAX_CACHE, else ~/.cache/mjx_pusht/jax), refused
    in one line where it or a folder above it is a file: checked before a command claims its --out (a file there was
    a FileExistsError traceback once the run's .run.json was written), and made (one that cannot be is refused)."""
    from pathlib import Path

    given = path or os.environ.get("MJX_PUSHT_JAX_CACHE")
    cache = Path(given or Path.home() / ".cache" / "mjx_pusht" / "jax")
    where = f"MJX_PUSHT_JAX_CACHE={given}" if given and not path else f"the JAX compile cache {cache}"
    for p in (cache, *cache.parents):
        if p.exists() and not p.is_dir():
            raise ConfigError(f"{where}: {p} is a file, not a folder: point it at a folder (XLA's compile cache, "
                              "made if missing) or unset it")
        if p.exists():
            break
    try:  # made here, at the door: a folder that cannot be made (/proc/x, no permission) is one line, not a traceback
        cache.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"{where}: cannot make the folder {cache} ({e.strerror}): point it at a folder this user "
                          "can write, or unset it") from None
    return cache


# Peak memory per item, measured (this 2-core CPU, peak RSS between two counts): an eval's episode (its table row,
# seeds, chunks: 150 MB at 16,384 seeds, 312 MB at 131,072; --max-steps 1) and a CPU vector env's world (its
# MjData and buffers: 312 MB at 256 envs, 2.06 GB at 4,096, after a reset and a step).
BYTES_PER_SEED = 1_500
BYTES_PER_CPU_ENV = 460_000


# --- the tables ------------------------------------------------------------------------------------------------
MAX_PROCESSES = 65_536
MAX_WORKERS = 4_096  # CPU threads or processes one backend may start
MAX_ENVS = 2**24  # one vector env's batch: past it the first arrays do not fit in this machine's nor an H200's memory

PROCESSES = {"process_id": Int(0), "num_processes": Int(1, MAX_PROCESSES), "coordinator": Maybe(Address()),
             "peer_timeout": Real(0, 7 * 24 * 3600.0, low_open=True)}
COMBINATIONS = {
    "processes": (
        (lambda v: v["coordinator"] is not None and v["num_processes"] == 1,
         "--coordinator {coordinator} joins several processes: give --num-processes N (N > 1) with it, or leave it "
         "out to run alone"),
        (lambda v: v["num_processes"] > 1 and v["coordinator"] is None,
         "several processes need --coordinator HOST:PORT (process 0's address)"),
        (lambda v: v["process_id"] >= v["num_processes"],
         lambda v: f"--process-id must be from 0 to {v['num_processes'] - 1}, got {v['process_id']}"),
    ),
    "functional_env": (
        (lambda v: v["graph_mode"] is not None and v["backend"] != "mjx-warp",
         "graph_mode {graph_mode!r} is MJX-Warp's CUDA-graph mode; backend {backend} has none: leave it None"),
        (lambda v: v.get("raster") and v["backend"] == "cpu",
         "raster=True draws MJX's pixels in JAX; the cpu backend renders with MuJoCo's own renderer: leave it False"),
        (lambda v: v["backend"] == "cpu" and any(v.get(k) is not None for k in ("contacts_per_world", "rows_per_world")),
         "contacts_per_world and rows_per_world size MJX's buffers; MuJoCo C on the cpu backend sizes its own: leave "
         "them None"),
    ),
}
_MJX = {"x64": Flag(), "iterations": Maybe(Int(1, 10_000)), "ls_iterations": Maybe(Int(1, 10_000)),
        "tolerance": Maybe(Real(0, 1, low_open=True)), "contacts_per_world": Maybe(Int(1, 10_000)),
        "constraints_per_world": Maybe(Int(1, 100_000)), "graph_mode": Maybe(Instance(str, "a graph mode's name")),
        "precompile": Flag(), "match_c_colliders": Flag(), "check_actions": Flag(), "devices": lambda n, v, e: v,
        "workers": Int(1, MAX_WORKERS), "nthread": Maybe(Int(1, MAX_WORKERS))}  # CPU threads: no use on a device
BACKEND_OPTIONS = {
    "cpu": {"nthread": Maybe(Int(1, MAX_WORKERS)), "workers": Int(1, MAX_WORKERS)},
    "gym-pusht": {"workers": Int(1, MAX_WORKERS)},  # one env a process there: the batch commands pass their own
    "mjx-jax": _MJX,
    "mjx-warp": _MJX,
}
FUNCTIONAL_ENV = {"backend": OneOf(("cpu", "mjx-jax", "mjx-warp")), "action_type": OneOf("mjx_pusht.task.rules:ACTION_TYPES"),
                  "reset_kind": OneOf("mjx_pusht.task.reset:RESETS"), "goal": OneOf("mjx_pusht.task.goals:GOALS"),
                  "scene": Instance("mjx_pusht.model.scene:SceneSpec", "a SceneSpec"),
                  "episode": Instance("mjx_pusht.task.episode:Episode", "an Episode"),
                  "keypoints": Flag(), "keep_states": Flag(), "raster": Flag(),
                  "threads": Int(1, MAX_WORKERS), "graph_mode": Maybe(Instance(str, "a graph mode's name")),
                  # MJX's buffers, as make_backend's (None: the measured defaults; -1 and 0 were taken as given)
                  "contacts_per_world": Maybe(Int(1, 10_000)), "rows_per_world": Maybe(Int(1, 100_000))}
CONTROLLER = Maybe(Instance("mjx_pusht.task.controller_base:Controller",
                            "a Controller (task.controllers.load('expert') makes one from its name)"))
# The reset options this package reads, and which entries honour each: an entry given one it cannot honour refuses
# it (a mask on one env was ignored).
RESET_OPTIONS = {"reset_to_state": "every env", "reset_mask": "a vector env"}
# Options others pass and no env here reads: ignored. Any other key is refused (a typo was silently ignored).
FOREIGN_RESET_OPTIONS = {"lerobot_new_rollout": "LeRobot's eval, on every rollout"}


def reset_options(options, honoured: tuple, where: str) -> None:
    """Refuse a reset option of this package's that `where` does not honour."""
    for name in sorted(set(options) & set(RESET_OPTIONS) - set(honoured)):
        if options[name] is not None:
            raise ConfigError(f"{where}.reset cannot honour options[{name!r}] (read by {RESET_OPTIONS[name]} only): "
                              "leave it out")


# A vector env's own attributes that set_attr may change, each with its rule (the next render reads render_size;
# the next step the success threshold, on every env of the batch, as the single env's attribute)
SETTABLE = {"render_size": Int(8, 2048), "success_threshold": Real(0, 1, low_open=True)}


def set_attr(env, name: str, value):
    """A vector env's `set_attr(name, value)`: `value` through the rule of a settable name (`SETTABLE`); any other
    name of the env's own (its batch size, spaces) is refused, since setting it would not change the running batch
    (num_envs); a name the env does not have is refused as `call` of it is (a typo was set and never read). Returns
    the value to set."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError(f"set_attr takes an attribute's name, got {_show(name)}")
    if name in SETTABLE:
        return SETTABLE[name](name, value)
    if not hasattr(env, name):
        raise UnknownAttribute(f"set_attr({name!r}): the vector env has no attribute {name!r}; it may set "
                               f"{', '.join(SETTABLE)}")
    raise ConfigError(f"set_attr({name!r}): {name} is the running vector env's own and cannot be changed "
                      f"(settable: {', '.join(SETTABLE)})")


class UnknownAttribute(MjxPushtError, AttributeError):
    """A vector env's `call`/`get_attr` of a name it does not have (an AttributeError, as SyncVectorEnv's)."""


def attribute(env, name) -> None:
    """A vector env's `call(name)`/`get_attr(name)`: an attribute's name that the env has."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ConfigError(f"call and get_attr take an attribute's name, got {_show(name)}")
    if name != "_max_episode_steps" and not hasattr(env, name):
        raise UnknownAttribute(f"the vector env has no attribute {name!r}")


def check_gym_pusht_obs(obs, obs_type: str) -> None:
    """A gym-pusht observation for a policy: obs_type "state", 5 finite numbers ([agent x, y, block x, y, angle]);
    "pixels_agent_pos", {"pixels": (H, W, 3) uint8, "agent_pos": 2 finite numbers}. A random goal's observation
    (8 numbers) is not one: the policy was trained toward the fixed goal."""
    if obs_type == "state":
        if isinstance(obs, dict):
            raise ConfigError(f"this policy reads gym-pusht's state observation (5 numbers), got a dict with "
                              f"{', '.join(map(str, obs))}: make the env with obs_type='state'")
        a = Array((-1,))("observation", obs)
        if a.shape != (5,):
            extra = " (a random goal's observation: this policy acts toward the fixed goal)" if a.shape == (8,) else ""
            raise ConfigError(f"observation must be gym-pusht's state, 5 numbers [agent x, y, block x, y, angle], "
                              f"got shape {a.shape}{extra}")
    elif obs_type == "pixels_agent_pos":
        if not isinstance(obs, dict) or set(obs) != {"pixels", "agent_pos"}:
            got = f"a dict with {', '.join(map(str, obs))}" if isinstance(obs, dict) else _show(obs)
            raise ConfigError(f"this pixel policy reads {{'pixels': (H, W, 3) uint8, 'agent_pos': (2,)}}, got {got}: "
                              "make the env with obs_type='pixels_agent_pos'")
        Array((2,))("observation['agent_pos']", obs["agent_pos"])
        img = Array((-1, -1, 3), kinds="u")("observation['pixels']", obs["pixels"])
        if img.dtype != np.uint8 or min(img.shape[:2]) < 1:
            raise ConfigError(f"observation['pixels'] must be (H, W, 3) uint8, got {img.dtype} of shape {img.shape}")
    else:
        raise ConfigError(f"unknown obs_type {_show(obs_type)}; choose from state, pixels_agent_pos")
