"""The run banner: which hardware tier ran it and how long it took (stdout, never metrics)."""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
import time


def gpu_name() -> str | None:
    """The first NVIDIA GPU's name, or None on a machine without one."""
    if not shutil.which("nvidia-smi"):
        return None
    try:
        out = subprocess.run(
            ["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True, text=True, timeout=10
        )
    except (OSError, subprocess.SubprocessError):
        return None
    names = [n.strip() for n in out.stdout.splitlines() if n.strip()]
    if out.returncode != 0 or not names:
        return None
    return names[0] + (f" x{len(names)}" if len(names) > 1 else "")


def tier() -> str:
    """`cpu (N cores)` or the GPU's name: what a figure was measured on."""
    gpu = gpu_name()
    if gpu:
        return gpu
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"cpu ({cores} cores, {platform.machine()})"


class Banner:
    """Prints the tier at start and the measured wall-clock at the end."""

    def __init__(self, artifact: str):
        self.artifact = artifact
        self.t0 = time.perf_counter()
        print(f"== mjx-pusht {artifact} | tier: {tier()}", flush=True)

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def done(self) -> None:
        print(f"== {self.artifact} wall-clock: {self.elapsed:.2f} s ({self.elapsed / 60:.3f} min, measured)", flush=True)
