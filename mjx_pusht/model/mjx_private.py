"""MJX's private modules, behind one door.

MJX ships a private copy of MuJoCo Warp (`mujoco.mjx.third_party.mujoco_warp`) and keeps its JAX collision
tables and its Warp renderer's context in modules with no promise of stability (`mujoco.mjx._src`,
`mujoco.mjx.warp`). This package reads them in three places: the Warp kernel precompiler (the modules one step
launches), the collider report (which function collides each geom pair) and the Warp renderer (where the
camera's pixels start). They are the first thing an MJX release may move, so every such import goes through this
module, which knows the MJX releases it was checked against and refuses any other in one line rather than
failing deep inside a step. docs/study/backends.md plans the move to the public `mujoco_warp` package.
It sits in `model`, the lowest layer that reads MJX (the collider report), so that render and backends, above it,
can use it too.
"""

from __future__ import annotations

import importlib
import importlib.metadata

from mjx_pusht.errors import MjxPushtError

# The mujoco-mjx release series whose private layout (the module paths below and the names read from them) was
# checked, each by this repository's suite. pyproject.toml's range for mujoco-mjx ends where this list does.
KNOWN_MJX = ("3.17",)

# Warp's module of the wrappers MJX registers with jax.ffi (JAX loads it when tracing an MJX-Warp call)
FFI_MODULE = "mujoco.mjx.warp.ffi"


class MjxVersionError(MjxPushtError, ImportError):
    """The installed MJX (or MuJoCo under it) is not a release whose private modules this package knows."""


def _installed(dist: str) -> str | None:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return None


def check() -> str:
    """The installed mujoco-mjx version if this package knows its private modules; else one line saying why not
    and what to install. Also refuses MuJoCo 3 beside MuJoCo 4's own parts (`mujoco-core`): what a downgrade from
    MuJoCo 4 leaves behind, which `pip check` does not see and a later upgrade breaks."""
    mjx = _installed("mujoco-mjx")
    if mjx is None:
        raise MjxVersionError("MJX is not installed: pip install 'mujoco-mjx>=3.17,<3.18'")
    if not any(mjx == k or mjx.startswith(k + ".") for k in KNOWN_MJX):
        raise MjxVersionError(
            f"mujoco-mjx {mjx} is installed, but mjx_pusht reads MJX's private modules and knows them only in "
            f"mujoco-mjx {', '.join(k + '.x' for k in KNOWN_MJX)}: pip install 'mujoco-mjx>=3.17,<3.18' "
            "(docs/install.md)")
    mujoco, core = _installed("mujoco"), _installed("mujoco-core")
    if mujoco and core and mujoco.split(".")[0] != core.split(".")[0]:
        raise MjxVersionError(
            f"mujoco {mujoco} is installed over mujoco-core {core}, left from another MuJoCo: pip install "
            f"'mujoco=={core}' (this package supports it) or pip uninstall mujoco-core mujoco-studio, then "
            f"pip install --force-reinstall 'mujoco=={mujoco}'")
    return mjx


def _module(name: str):
    check()
    return importlib.import_module(name)


def mujoco_warp():
    """MJX's private copy of MuJoCo Warp (put_model, put_data, step)."""
    return _module("mujoco.mjx.third_party.mujoco_warp")


def warp_collision():
    """MuJoCo Warp's collision driver, primitive colliders and types (its pair table, its primitive functions)."""
    base = "mujoco.mjx.third_party.mujoco_warp._src."
    return tuple(_module(base + m) for m in ("collision_driver", "collision_primitive", "types"))


def jax_collision():
    """MJX-JAX's collision driver and types (its pair -> function table)."""
    return tuple(_module("mujoco.mjx._src." + m) for m in ("collision_driver", "types"))


def render_context():
    """MJX-Warp's renderer context module (where each camera's pixels start in the shared buffer)."""
    return _module("mujoco.mjx.warp.render_context")
