"""The errors a user can cause or meet; the CLI prints each as one line."""

from __future__ import annotations

from mjx_pusht.backends import BackendError
from mjx_pusht.controllers import ControllerError
from mjx_pusht.distributed import DistributedError
from mjx_pusht.outputs import OutputError
from mjx_pusht.params import ParamError
from mjx_pusht.pixels import PixelsError
from mjx_pusht.rollout_mjx import BufferOverflow
from mjx_pusht.seeds import SeedSpecError
from mjx_pusht.sweep import ResumeError
from mjx_pusht.tree import TreeMismatch
from mjx_pusht.video import VideoError

KNOWN_ERRORS: tuple[type[BaseException], ...] = (
    BackendError, ControllerError, DistributedError, OutputError, ParamError, BufferOverflow, SeedSpecError, ResumeError, TreeMismatch, PixelsError, VideoError, ValueError,
)
