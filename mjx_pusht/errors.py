"""The errors a user can cause or meet; the CLI prints each as one line."""

from __future__ import annotations

from mjx_pusht.backends.base import BackendError
from mjx_pusht.task.controllers import ControllerError
from mjx_pusht.study.distributed import DistributedError
from mjx_pusht.io.outputs import OutputError
from mjx_pusht.model.params import ParamError
from mjx_pusht.envs.pixels import PixelsError
from mjx_pusht.backends.mjx import BufferOverflow
from mjx_pusht.study.seeds import SeedSpecError
from mjx_pusht.study.sweep import ResumeError
from mjx_pusht.model.tree import TreeMismatch
from mjx_pusht.io.video import VideoError

KNOWN_ERRORS: tuple[type[BaseException], ...] = (
    BackendError, ControllerError, DistributedError, OutputError, ParamError, BufferOverflow, SeedSpecError, ResumeError, TreeMismatch, PixelsError, VideoError, ValueError,
)
