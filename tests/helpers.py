"""Helpers the test files share (imported as `helpers`: pytest puts this folder on sys.path)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

from mjx_pusht.task.episode import Episode

EPISODE = Episode()  # 10 Hz control, 300 steps
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def cli(*args, cwd=None, env=None) -> subprocess.CompletedProcess:
    """`python -m mjx_pusht ARGS` as a user runs it."""
    return subprocess.run([sys.executable, "-m", "mjx_pusht", *args], capture_output=True, text=True,
                          cwd=cwd, env=env or ENV)


def pixels_refusal(env: dict) -> subprocess.CompletedProcess:
    """A pixel env reset in a fresh process under `env` (a MUJOCO_GL set aside at import): prints REFUSED and the
    PixelsError's message when the renderer refuses."""
    code = ("import gymnasium as gym, mjx_pusht\n"
            "from mjx_pusht.render.pixels import PixelsError\n"
            "try:\n    gym.make('mjx_pusht/PushT-v0', obs_type='pixels').reset(seed=0)\n"
            "except PixelsError as e:\n    print('REFUSED', e)\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=os.getcwd())


# The cheapest run of each command (the refusal tests' base: their refusals come before any simulation)
RUNS = {
    "sweep": ("sweep", "--backend", "cpu", "--seeds", "2", "--steps", "5", "--no-rerun", "--no-progress"),
    "eval": ("eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-rerun", "--no-progress"),
    "scene": ("scene", "--no-rerun"),
    "compare": ("compare", "--backend", "mjx-warp", "--seeds", "2"),
    "train": ("train", "--backend", "cpu", "--envs", "8", "--iterations", "1", "--fit-steps", "5", "--hidden", "16",
              "--eval-envs", "8", "--no-rerun", "--record", "0", "--no-progress"),
    "demos": ("demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "5", "--no-progress"),
}

def over(base, *extra) -> list:
    """`base`'s arguments with `extra`'s flags in place of its own (each flag's value, if it has one, goes with it):
    the CLI refuses a flag given twice, so a test's other settings replace the base's rather than follow them."""
    return [*without(base, {a for a in extra if str(a).startswith("--")}), *extra]


def without(base, flags) -> list:
    """`base`'s arguments less each of `flags` and its value, if it has one."""
    out, i = [], 0
    while i < len(base):
        if base[i] in flags:
            i += 2 if i + 1 < len(base) and not str(base[i + 1]).startswith("--") else 1
            continue
        out.append(base[i])
        i += 1
    return out


def one_line(capsys, *words) -> str:
    """The one stderr line a refused command printed (capsys), holding each of `words`."""
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert all(w in err[0] for w in words), err[0]
    return err[0]


def train_run(tmp_path_factory, *args):
    """`mjx-pusht train ARGS --out DIR` in a fresh temporary folder, as a user runs it; DIR when it succeeded."""
    out = tmp_path_factory.mktemp("train") / "run"
    r = cli("train", *args, "--out", str(out))
    assert r.returncode == 0, r.stderr
    return out


def assert_matches_cpu(mjx, cpu) -> None:
    """MJX rows against the CPU's: the same starts, the contact-free settle to float32, every verdict equal."""
    np.testing.assert_array_equal(mjx.start, cpu.start)
    np.testing.assert_allclose(mjx.settled, cpu.settled, atol=1e-5)  # no contact yet: float32 rounding only
    np.testing.assert_allclose(mjx.gap_settled, cpu.gap_settled, atol=1e-5)
    np.testing.assert_array_equal(mjx.rigid, cpu.rigid)
    assert mjx.finite.all()


SMALL_PPO = dict(obs_type="state", envs=8, timesteps=10240, evals=1, hidden=(32, 32), batch_size=8, eval_envs=4,
                 max_steps=50)


def brax_ppo_arguments(monkeypatch, tmp_path, runs) -> list[dict]:
    """The keyword arguments `train_ppo` hands Brax's own `ppo.train`, one dict for each (PPOConfig, train_ppo's
    keyword arguments) of `runs`; Brax's trainer is stopped at its call, so nothing compiles."""
    import pytest
    from brax.training.agents.ppo import train as brax_ppo

    from mjx_pusht.train.ppo import train_ppo

    given = []

    class Called(Exception):
        pass

    def train(**kwargs):
        given.append(kwargs)
        raise Called

    monkeypatch.setattr(brax_ppo, "train", train)
    for cfg, kwargs in runs:
        with pytest.raises(Called):
            train_ppo(cfg, "mjx-jax", tmp_path / str(len(given)), progress=False, **kwargs)
    return given
