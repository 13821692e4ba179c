"""LeRobot's own tools on mjx_pusht, offline: lerobot 0.6.1's `lerobot-eval` and `lerobot-train` run as a user
runs them (subprocesses of this venv's console scripts), with nothing fetched from the Hugging Face Hub."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

OFFLINE = {"HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1", "WANDB_MODE": "disabled"}
os.environ.update(OFFLINE)
BIN = Path(sys.executable).parent
HERE = Path(__file__).parent


def run(tool: str, *args: str, cwd: Path, timeout: int = 900) -> subprocess.CompletedProcess:
    """A console script of this venv, offline; its output is shown if it fails."""
    p = subprocess.run([str(BIN / tool), *args], cwd=cwd, env={**os.environ, **OFFLINE}, capture_output=True,
                       text=True, timeout=timeout)
    assert p.returncode == 0, f"{tool} exited {p.returncode}:\n{p.stdout[-3000:]}\n{p.stderr[-6000:]}"
    return p


@pytest.fixture(scope="session")
def tiny_policy(tmp_path_factory) -> Path:
    """A small ACT policy (LeRobot's classes, random weights, save_pretrained), 96 x 96 images."""
    sys.path.insert(0, str(HERE))
    from tiny_policy import make_tiny_policy

    return make_tiny_policy(tmp_path_factory.mktemp("policy") / "act")


@pytest.fixture(scope="session")
def demos(tmp_path_factory) -> Path:
    """Two expert episodes from `mjx-pusht demos` on MuJoCo C, truncated at 60 steps."""
    out = tmp_path_factory.mktemp("demos") / "pusht_demos"
    run("mjx-pusht", "demos", "--seeds", "2", "--backend", "cpu", "--max-steps", "60", "--out", str(out),
        "--no-progress", cwd=out.parent)
    return out
