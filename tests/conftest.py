"""Shared, compiled-once fixtures: XLA compiles once per batch shape, so MJX runs are session-scoped."""

from __future__ import annotations

import importlib.metadata
import os

import numpy as np
import pytest

os.environ.setdefault("MJX_PUSHT_JAX_CACHE", os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))

from mjx_pusht.model.scene import SceneSpec  # noqa: E402
from mjx_pusht.scenario import Scenario  # noqa: E402

SEEDS = np.arange(8)

# tests/lerobot/ runs LeRobot's own lerobot-eval and lerobot-train (lerobot 0.6.1 needs Python 3.12): it is
# collected only where lerobot is installed, the venv `make test-lerobot` builds (asked of the installed
# distributions: `import lerobot` would find tests/lerobot/ itself, a namespace package, where it is not)
try:
    importlib.metadata.version("lerobot")
    collect_ignore = []
except importlib.metadata.PackageNotFoundError:
    collect_ignore = ["lerobot"]


def pytest_collection_modifyitems(config, items):
    """`warp` tests skip, saying why, where warp-lang is not installed (they run everywhere it is, CI included)."""
    from mjx_pusht.backends.warp import warp_available

    if warp_available():
        return
    skip = pytest.mark.skip(reason="warp-lang is not installed (pip install 'mjx-pusht[warp]')")
    for item in items:
        if "warp" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def _run_in_a_temporary_directory(tmp_path, monkeypatch):
    """Every test runs in its own folder: whatever it writes by default (MuJoCo's MUJOCO_LOG.TXT,
    outputs/...) lands there, never in the checkout."""
    monkeypatch.chdir(tmp_path)


@pytest.fixture(scope="session")
def cpu_runs():
    """The CPU reference for seeds 0..7, welded and split, cylinder and capsule pusher."""
    from mjx_pusht.backends.cpu import run_cpu

    return {
        (b, p): run_cpu(Scenario(SceneSpec(b, p)), SEEDS)
        for b in ("none", "split-tee")
        for p in ("cylinder", "capsule")
    }


@pytest.fixture(scope="session")
def mjx_jax_runs():
    from mjx_pusht.backends.mjx import MjxBackend

    return {b: MjxBackend(Scenario(SceneSpec(b)), "jax").run(SEEDS) for b in ("none", "split-tee")}


@pytest.fixture(scope="session")
def mjx_warp_runs():
    from mjx_pusht.backends.mjx import MjxBackend
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    return {b: MjxBackend(Scenario(SceneSpec(b)), "warp").run(SEEDS) for b in ("none", "split-tee")}
