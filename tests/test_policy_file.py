"""A policy file of the wrong types or shapes is one line naming what is wrong (train/policy.py reads it), in the
Python API and in the CLI, never NumPy's "could not convert string to float" from deep in a rollout."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.task.controllers import ControllerError, load
from mjx_pusht.train.policy import OUTPUTS, feature_size, save
from tests.helpers import cli

W = feature_size("state")


def _good():
    """The smallest state policy this version reads: two Dense layers from the features to (action, memory)."""
    meta = {"obs_type": "state", "activation": "relu", "method": "dagger", "in_mean": [0.0] * W, "in_std": [1.0] * W}
    params = {"Dense_0": {"kernel": np.zeros((W, 8)), "bias": np.zeros(8)},
              "Dense_1": {"kernel": np.zeros((8, OUTPUTS)), "bias": np.zeros(OUTPUTS)}}
    return params, meta


BAD = {  # what the file holds -> the words of the one line
    "a string in in_mean": (lambda p, m: m.update(in_mean=["0.0"] * (W - 1) + ["x"]), "in_mean holds something other"),
    "strings in in_std": (lambda p, m: m.update(in_std=["one"] * W), "in_std holds something other"),
    "a zero in in_std": (lambda p, m: m.update(in_std=[0.0] * W), "in_std must be positive"),
    "a NaN in in_mean": (lambda p, m: m.update(in_mean=[float("nan")] * W), "in_mean holds non-finite"),
    "in_mean missing": (lambda p, m: m.pop("in_mean"), "in_mean holds something other"),
    "a nested in_mean": (lambda p, m: m.update(in_mean={"a": 1}), "in_mean holds something other"),
    "in_mean too short": (lambda p, m: m.update(in_mean=[0.0] * 3), f"in_mean has shape (3,), not ({W},)"),
    "an obs type list": (lambda p, m: m.update(obs_type=["state"]), "unknown obs type"),
    "an image size string": (lambda p, m: m.update(image="96"), "image size '96'"),
    "a PPO act list": (lambda p, m: m.update(method="ppo", act=["mean"], in_mean=[0.0] * 5, in_std=[1.0] * 5),
                       "unknown PPO action"),
    "a layer that is a number": (lambda p, m: p.update(Dense_1=3.0), "not named layers"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_policy_file_of_the_wrong_types_is_one_line(case, tmp_path):
    params, meta = _good()
    load(f"policy:{_write(tmp_path / 'good.msgpack', params, meta)}")  # the good file loads
    change, words = BAD[case]
    change(params, meta)
    path = _write(tmp_path / "bad.msgpack", params, meta)
    with pytest.raises(ControllerError) as e:
        load(f"policy:{path}")
    assert words in str(e.value) and "\n" not in str(e.value)


def test_a_string_in_the_kernel_is_one_line():
    from mjx_pusht.train.policy import _check

    params, meta = _good()
    params["Dense_0"]["kernel"] = np.full((W, 8), "0.5")
    with pytest.raises(ControllerError, match="Dense_0's weights holds something other than numbers"):
        _check("p.msgpack", params, meta)


def test_the_cli_says_it_in_one_line_and_writes_no_table(tmp_path):
    params, meta = _good()
    meta["in_mean"] = ["x"] * W
    path = _write(tmp_path / "bad.msgpack", params, meta)
    r = cli("eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "2", "--no-rerun", "--controller",
            f"policy:{path}", "--out", str(tmp_path / "e"))
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and "in_mean" in r.stderr, r.stderr
    assert not (tmp_path / "e" / "per_episode.parquet").exists()


def _write(path, params, meta):
    save(path, params, {k: v for k, v in meta.items() if k != "format"})
    return path
