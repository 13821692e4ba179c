"""Comparison of MJX with the CPU reference: outcome distances and modes, and a small compare run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mjx_pusht.backends.results import Rollouts
from mjx_pusht.study.outcomes import energy_distance, outcome_modes


def test_energy_distance_is_zero_for_identical_samples_and_grows_with_a_shift():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(300, 3))
    assert energy_distance(a, a) == pytest.approx(0.0, abs=1e-12)
    # for two point masses the energy distance is exactly 2|d|
    assert energy_distance(np.zeros((5, 3)), np.full((5, 3), [0.0, 0.0, 0.5])) == pytest.approx(1.0)


def test_outcome_modes_split_on_final_yaw():
    z = np.zeros((4, 3))
    final = np.array([[0, 0, 0.1], [0, 0, 1.2], [0, 0, -1.2], [0, 0, -0.2]])
    r = Rollouts(np.arange(4), z, z, final, np.zeros((4, 2)), np.zeros(4), np.zeros(4), np.ones(4, bool), np.ones(4, bool))
    assert outcome_modes(r) == {"straight": 0.5, "spun_ccw": 0.25, "spun_cw": 0.25}


@pytest.mark.slow
def test_compare_on_a_few_seeds_agrees_where_it_must(tmp_path):
    from mjx_pusht.cli.commands import main

    assert main(["compare", "--seeds", "6", "--backend", "mjx-jax", "--out", str(tmp_path), "--no-root-cause"]) == 0
    r = json.loads((tmp_path / "compare.json").read_text())
    for variant in ("none", "split-tee"):
        assert r[variant]["settle_max_abs_err"] <= 1e-5
        assert r[variant]["verdict_agreement"] == 1.0
    assert r["none"]["structure"]["pusher_shape"] == "capsule"
    assert isinstance(r["outcomes"]["outcome_within_cpu_baseline"], bool)
    assert "# CPU vs mjx-jax" in (tmp_path / "compare.md").read_text()
    assert (tmp_path / "compare.png").read_bytes()[:4] == b"\x89PNG"


# --- the task score -------------------------------------------------------------
