"""Issue 23's findings, each made small: bad input is one line and a non-zero exit, nothing written is lost."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import cli

from mjx_pusht.study.seeds import SeedSpecError, parse_seeds

gym = pytest.importorskip("gymnasium")
import mjx_pusht  # noqa: E402,F401

ENV = "mjx_pusht/PushT-v0"


@pytest.mark.parametrize("spec", ["9223372036854775807", "10000000000", "0:9223372036854775807"])
def test_a_seed_count_beyond_one_run_is_refused_not_an_empty_table(spec):
    with pytest.raises(SeedSpecError, match="at most 2"):
        parse_seeds(spec)


def test_a_huge_seed_count_leaves_a_finished_folder_as_it_was(tmp_path):
    out = tmp_path / "done"
    out.mkdir()
    (out / "per_seed.parquet").write_bytes(b"finished results")
    r = cli("sweep", "--backend", "cpu", "--seeds", "9223372036854775807", "--out", str(out))
    assert r.returncode != 0
    assert len(r.stderr.strip().splitlines()) == 1 and "at most 2**30" in r.stderr
    assert (out / "per_seed.parquet").read_bytes() == b"finished results"


@pytest.mark.parametrize("bad", [np.zeros(3), 0.5, None])
def test_single_env_actions_of_the_wrong_shape_are_one_line(bad):
    env = gym.make(ENV)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        env.step(bad)


def test_vector_env_inputs_are_checked_up_front():
    envs = gym.make_vec(ENV, num_envs=3, backend="cpu")
    with pytest.raises(ValueError, match="first reset starts every environment"):
        envs.reset(options={"reset_mask": np.array([True, False, False])})
    with pytest.raises(ValueError, match="reset_to_state"):
        envs.reset(options={"reset_to_state": np.zeros((5, 5))})
    with pytest.raises(ValueError, match="finite"):
        envs.reset(options={"reset_to_state": [np.nan, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match="unknown reset option"):
        envs.reset(options={"reset_mask_typo": True})
    with pytest.raises(ValueError, match="a seed is an integer"):
        envs.reset(seed=2**64)
    with pytest.raises(ValueError, match="num_envs must be a positive integer"):
        gym.make_vec(ENV, num_envs=2.7, backend="cpu")
    with pytest.raises(ValueError, match="image size"):
        gym.make_vec(ENV, num_envs=2, backend="cpu", obs_type="pixels", observation_size=0)
    env = gym.make(ENV)
    with pytest.raises(ValueError, match="a seed is an integer"):
        env.reset(seed=2**64)
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"reset_to": [0, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match="finite"):
        env.reset(options={"reset_to_state": [0, 0, np.inf, 0, 0]})
