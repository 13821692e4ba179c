"""mjx_pusht: the planar PushT pushing task in MuJoCo, CPU reference and MJX batch.

The library API: build a `Scenario`, pick a backend, run seeds, read `Rollouts`.

    from mjx_pusht import Scenario, make_backend
    rows = make_backend("cpu", Scenario()).run(range(8))
"""

import importlib.util as _util
import os as _os
import sys as _sys


def _end_early(signum, frame):  # noqa: ARG001 - a signal handler's signature
    _os.write(2, b"\nmjx-pusht: interrupted before the command started: nothing was written\n")
    _os._exit(128 + signum)


# The command line's own process (`mjx-pusht ...`, `python -m mjx_pusht ...`): a Ctrl-C or SIGTERM while this package
# imports (about a second: the GL probe's ldconfig, NumPy, MuJoCo, gymnasium) ends it in one line, before any file is
# written, not in a KeyboardInterrupt traceback; the CLI's main() takes both signals over once it runs. Set first: the
# GL probe below ran before it, and a Ctrl-C in its ldconfig was a traceback. A library import sets nothing.
_argv = getattr(_sys, "orig_argv", [])
if any(a == "-m" and b == "mjx_pusht" for a, b in zip(_argv, _argv[1:])) or (
        len(_argv) > 1 and _os.path.basename(_argv[1]) == "mjx-pusht"):
    import signal as _signal

    for _sig in (_signal.SIGINT, _signal.SIGTERM):
        if _signal.getsignal(_sig) is not _signal.SIG_IGN:
            _signal.signal(_sig, _end_early)

# Headless by default: MuJoCo picks its OpenGL when it is first imported, and on a machine with
# no screen GLFW cannot open one. EGL renders without a display (MUJOCO_GL=osmesa for OSMesa).
# Only where the library is there: MuJoCo imports the one it is told to at once, and fails without it.
if _sys.platform.startswith("linux") and not _os.environ.get("DISPLAY") and "MUJOCO_GL" not in _os.environ:
    import ctypes.util as _cu

    for _gl, _lib in (("egl", "EGL"), ("osmesa", "OSMesa")):
        if _cu.find_library(_lib):
            _os.environ["MUJOCO_GL"] = _gl
            break
# A MUJOCO_GL whose library is missing breaks `import mujoco` itself, so every command would die at
# import, `tree` and `sweep` included, that never draw. Only pixels need GL: the setting is set aside
# here and the renderer (render/pixels.py) refuses in one line, naming it, when pixels are asked for.
elif _os.environ.get("MUJOCO_GL") in ("egl", "osmesa") and _sys.platform.startswith("linux"):
    import ctypes.util as _cu

    if not _cu.find_library({"egl": "EGL", "osmesa": "OSMesa"}[_os.environ["MUJOCO_GL"]]):
        _os.environ["MJX_PUSHT_GL_MISSING"] = _os.environ.pop("MUJOCO_GL")
# A MUJOCO_GL that is no GL at all (a typo) breaks `import mujoco` the same way: set aside too, the renderer naming
# it and the names MuJoCo takes (its own list, mujoco/rendering/classic/gl_context.py) when pixels are asked for.
elif _os.environ.get("MUJOCO_GL", "").lower().strip() not in (
        "", "disable", "disabled", "off", "false", "0", "enable", "enabled", "on", "true", "1", "glfw",
        *{"linux": ("glx", "egl", "osmesa"), "win32": ("wgl",), "darwin": ("cgl",)}.get(_sys.platform, ())):
    _os.environ["MJX_PUSHT_GL_INVALID"] = _os.environ.pop("MUJOCO_GL")


# MJX-Warp allocates scratch through Warp, outside XLA's pool: with JAX holding its default 75% of the
# GPU up front, a 65,536-world environment step failed to allocate 2.3 GB (H100, the gymnasium vector env's
# step: notebook change 9).
# JAX then grows its pool as it needs instead; a user's own setting wins.
_os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
# One OpenBLAS thread (read when NumPy loads, so only where NumPy is not loaded yet): a policy's NumPy products run
# beside MuJoCo C's worker threads (DAgger's CPU rollouts, in this process), and OpenBLAS's threads then wait on
# theirs: on 2 cores one forward pass of 32 rows took 31 ms with its default, 0.48 ms with one thread (notebook
# firsthour). The CPU backend's worker processes start with one already (backends/cpu.py); a user's setting wins.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from mjx_pusht.backends.base import resolve
from mjx_pusht.backends.factory import make_backend
from mjx_pusht.backends.results import Rollouts
from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.model.tree import EXPECTED_TREES, Tree, TreeMismatch
from mjx_pusht.scenario import Scenario
# the helpers, each argument checked at the door (api.py); the package's own code calls them unchecked
from mjx_pusht.api import (build_model, check_tree, gap_deviation, read_tree, scene_xml, start_pose, start_poses,
                           stayed_rigid, weld_gap)
from mjx_pusht.api import keywords as _keywords
from mjx_pusht.task.episode import Episode as _Episode
from mjx_pusht.task.schedule import Schedule

# The exported constructors and functions bind their arguments at the door: a keyword they do not take, a missing
# argument or one given twice is one line naming what they take (api.keywords), not Python's TypeError traceback.
for _cls in (Scenario, SceneSpec, Schedule, _Episode):  # Episode: the functional env's, documented there
    _cls.__init__ = _keywords(_cls.__init__)
resolve, make_backend = _keywords(resolve), _keywords(make_backend)
from mjx_pusht.train.controller import register_policy as _register_policy

# `--controller policy:PATH` (and `task.controllers.load("policy:PATH")`) without importing the training layer:
# the task layer keeps a registry of controller prefixes, and training's is registered here, at the top
_register_policy()

__all__ = [
    "EXPECTED_TREES", "Rollouts", "Scenario", "SceneSpec", "Schedule", "Tree", "TreeMismatch",
    "build_model", "check_tree", "gap_deviation", "make_backend", "read_tree", "resolve", "scene_xml",
    "start_pose", "start_poses", "stayed_rigid", "weld_gap",
]
__version__ = "0.1.0"

if _util.find_spec("gymnasium") is not None:  # gym.make("mjx_pusht/PushT-v0") after `import mjx_pusht`
    from mjx_pusht.envs.gym import register as _register

    _register()
