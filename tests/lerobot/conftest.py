"""LeRobot's own tools on mjx_pusht, offline: lerobot 0.6.1's `lerobot-eval` and `lerobot-train` run as a user
runs them (subprocesses of this venv's console scripts), with nothing fetched from the Hugging Face Hub."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

OFFLINE = {"HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "TRANSFORMERS_OFFLINE": "1", "WANDB_MODE": "disabled"}
# one thread a torch process: pytest runs two workers on CI's two cores, and torch's own thread pool in each
# oversubscribes them (a diffusion policy's lerobot-eval took 30 s instead of 10 on this 2-core machine)
ONE_THREAD = {"OMP_NUM_THREADS": "1"}
os.environ.update(OFFLINE | ONE_THREAD)
BIN = Path(sys.executable).parent
HERE = Path(__file__).parent


def run(tool: str, *args: str, cwd: Path, timeout: int = 900) -> subprocess.CompletedProcess:
    """A console script of this venv, offline; its output is shown if it fails."""
    p = subprocess.run([str(BIN / tool), *args], cwd=cwd, env={**os.environ, **OFFLINE, **ONE_THREAD},
                       capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, f"{tool} exited {p.returncode}:\n{p.stdout[-3000:]}\n{p.stderr[-6000:]}"
    return p


EPISODE = 20  # control steps an eval episode (gym-pusht's 300 would take minutes on two CPU cores)


def lerobot_eval(policy, out, *env_args):
    """lerobot-eval of `policy` (a checkpoint's pretrained_model), two episodes of EPISODE steps on the env the
    arguments name; its eval_info.json, checked: two episodes, finite returns, a video of each."""
    run("lerobot-eval", f"--policy.path={policy}", "--policy.device=cpu", "--policy.use_amp=false",
        "--eval.batch_size=2", "--eval.n_episodes=2", f"--output_dir={out}", f"--env.episode_length={EPISODE}",
        *env_args, cwd=out.parent)
    info = json.loads((out / "eval_info.json").read_text())
    (task,) = info["per_task"]
    episodes = [dict(zip(("sum_reward", "success"), x, strict=True))
                for x in zip(task["metrics"]["sum_rewards"], task["metrics"]["successes"], strict=True)]
    assert info["overall"]["n_episodes"] == 2 and len(episodes) == 2
    assert all(np.isfinite(e["sum_reward"]) and e["sum_reward"] >= 0 for e in episodes)
    videos = sorted(out.glob("videos/*/eval_episode_*.mp4"))
    assert len(videos) == 2 and all(v.stat().st_size > 0 for v in videos)
    return info


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
