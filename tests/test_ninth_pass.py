"""The ninth hostile pass's findings, each run again as written (docs/notebook/hostile9.md; what changed for each:
docs/notebook/boundary.md, "After the ninth pass")."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from fuzzing import snapshot
from helpers import RUNS, one_line

import mjx_pusht  # noqa: F401 - registers the gym ids
from mjx_pusht.cli import main
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.wrappers import AutoReset
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

POLICY = Path(__file__).parent.parent / "outputs/reports/train/ppo-state-gym-pusht-h200/seed-0/policy.msgpack"


def test_another_commands_run_file_alone_is_its_run(tmp_path, capsys):
    """LOST (ninth pass): `sweep --share-out` into a finished `demos` folder rewrote the dataset's .run.json (a
    dataset's files are not results another command's claim counted). Refused whatever the flags; the dataset's own
    rerun still goes."""
    out = tmp_path / "d"
    assert main([*RUNS["demos"], "--out", str(out)]) == 0, capsys.readouterr().err
    capsys.readouterr()
    before = snapshot(out)
    for extra in ([], ["--share-out"], ["--share-out", "--replace"]):
        assert main([*RUNS["sweep"], "--out", str(out), *extra]) == 1
        one_line(capsys, "demos's results (.run.json)", "another command's results")
        assert snapshot(out) == before


@pytest.mark.parametrize("make", [
    lambda: gym.make("mjx_pusht/PushT-v0", observation_size=96.0),
    lambda: gym.make("mjx_pusht/PushT-gym-pusht-v0", observation_width=96.0, observation_height=96.0),
    lambda: gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu", observation_size=64.0),
])
def test_an_image_size_is_an_integer(make):
    """TRACEBACK (ninth pass): observation_size=96.0 passed the check (a whole number) and reached gymnasium's Box as
    a float shape: a TypeError from the space. A size is an integer, as every count is."""
    with pytest.raises(MjxPushtError, match="must be an integer from 8 to 2048, got 96.0|got 64.0"):
        make()


@pytest.mark.parametrize("kw", [{"final_pixels": "no"}, {"donate": 1}, {"image_pool": "no"}])
def test_autoresets_switches_are_booleans(kw):
    """SILENT (ninth pass): AutoReset(env, image_pool="no") was taken as True."""
    with pytest.raises(MjxPushtError, match="must be True or False"):
        AutoReset(PushTEnv(), **kw)


def test_a_gym_pusht_policys_calls_bind_their_arguments():
    """TRACEBACK (ninth pass): `policy.reset(bogus=1)` and `policy(obs, 3)` were Python's TypeError."""
    policy = GymPushtPolicy(POLICY)
    obs = np.array([100.0, 100.0, 200.0, 200.0, 1.0])
    with pytest.raises(MjxPushtError, match="reset.. got an unexpected keyword argument 'bogus'; it takes seed"):
        policy.reset(bogus=1)
    with pytest.raises(MjxPushtError, match="too many positional arguments; it takes obs"):
        policy(obs, 3)
    assert np.isfinite(policy(obs)).all()


@pytest.mark.parametrize("call, needle", [
    (lambda env, s: env.reset(), "missing a required argument: 'seeds'"),
    (lambda env, s: env.step(s), "missing a required argument: 'action'"),
    (lambda env, s: env.step(s, np.zeros((2, 2)), bogus=1), "unexpected keyword argument 'bogus'"),
    (lambda env, s: env.reset(np.arange(2), bogus=1), "unexpected keyword argument 'bogus'"),
    (lambda env, s: env.reset_to(), "missing a required argument: 'starts'"),
    (lambda env, s: env.reset_where(s), "missing a required argument: 'mask'"),
    (lambda env, s: __import__("mjx_pusht").make_backend("cpu", __import__("mjx_pusht").Scenario()).run(),
     "CpuBackend.run() missing a required argument: 'seeds'"),
    (lambda env, s: gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu").set_attr("success_threshold"),
     "missing a required argument: 'values'"),
    (lambda env, s: __import__("mjx_pusht").build_model(__import__("mjx_pusht").SceneSpec(), validate="no"),
     "validate must be True or False"),
])
def test_public_methods_bind_their_arguments(call, needle):
    """TRACEBACK (ninth pass, 12 tries): the functional env's reset/step/reset_to/reset_where, a backend's run and
    the vector env's set_attr given a missing or unknown argument were Python's TypeError; SILENT: build_model's
    validate="no" was taken as True."""
    env = PushTEnv()
    state = env.reset(np.arange(2))
    with pytest.raises(MjxPushtError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        call(env, state)


@pytest.mark.parametrize("flag", [["--success-threshold", "0.9"], ["--backend", "mjx-warp"], ["--reset", "easy"],
                                  ["--goal", "random"], ["--no-root-cause"]])
def test_compare_evals_refuses_the_settings_of_a_run(tmp_path, capsys, flag):
    """SILENT (ninth pass, 6 tries): `compare --evals A B` took --success-threshold, --backend, --reset, --goal and
    --no-root-cause and ignored them (the report was the same); it runs nothing, so they are refused."""
    assert main(["compare", "--evals", str(tmp_path / "a"), str(tmp_path / "b"), *flag,
                 "--out", str(tmp_path / "c")]) == 2
    one_line(capsys, f"so {flag[0]} is not taken")
    assert not (tmp_path / "c").exists()
