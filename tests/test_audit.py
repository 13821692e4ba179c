"""The audit: an MJX sweep re-runs a sample of its rows on the CPU reference and says whether they agree."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.backends.mjx import MjxBackend
from mjx_pusht.cli.commands import main
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.audit import MIN_ROWS, announce, audit, compare_rows, sample_rows


def test_the_sample_is_seeded_bounded_and_takes_every_flagged_row():
    flagged = np.zeros(10_000, bool)
    flagged[[7, 9_999]] = True
    a = sample_rows(10_000, 0.01, flagged)
    assert np.array_equal(a, sample_rows(10_000, 0.01, flagged))  # the same rows every time
    assert 100 <= len(a) <= 102  # 1% of the rows, plus the flagged ones not already drawn
    assert {7, 9_999} <= set(a.tolist())
    assert len(sample_rows(1000, 0.01, np.zeros(1000, bool))) == MIN_ROWS  # at least 64
    assert len(sample_rows(10, 0.01, np.zeros(10, bool))) == 10  # never more rows than the sweep has


def test_the_cpu_agrees_with_itself():
    r = run_cpu(Scenario(), np.arange(64))
    block = compare_rows(r, r)
    assert block["agrees"] and block["settle_max_abs_err"] == 0.0 and block["fraction_final_over_1mm"] == 0.0


@pytest.mark.slow
@pytest.mark.warp
def test_a_backend_with_another_kv_under_the_hood_fails_the_audit_loudly(capsys, tmp_path):
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    seeds = np.arange(64)
    # the faithful batch agrees ...
    good = MjxBackend(Scenario(), "warp")
    block = audit(good, good.run(seeds), np.zeros(64, np.int64), 1.0, welded=True, out=tmp_path)
    assert block["agrees"], block
    assert (tmp_path / "audit_cpu.parquet").exists()
    # ... one whose servo gain is 5 instead of the authored 20, while it claims the authored scene, does not
    wrong = MjxBackend(Scenario(params=(("kv", (5.0,)),)), "warp")
    rows = wrong.run(seeds)
    wrong.scenario = Scenario()  # what it says it simulated
    bad = audit(wrong, rows, np.zeros(64, np.int64), 1.0, welded=True)
    assert not bad["agrees"] and bad["settle_max_abs_err"] <= 1e-5  # the settle is contact-free: kv cannot show there
    assert bad["fraction_final_over_1mm"] > 0.5
    announce(bad)
    err = capsys.readouterr().err
    assert "DOES NOT AGREE WITH THE CPU REFERENCE" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
@pytest.mark.warp
def test_an_mjx_sweep_records_its_audit_beside_the_table(tmp_path, capsys):
    from mjx_pusht.backends.warp import warp_available

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    out = tmp_path / "w"
    assert main(["sweep", "--seeds", "8", "--backend", "mjx-warp", "--out", str(out), "--no-rerun", "--no-progress"]) == 0
    a = json.loads((out / "summary.json").read_text())["audit"]
    assert a["agrees"] and a["n_rows"] == 8 and a["verdict_agreement"] == 1.0 and a["cpu_rows"] == "audit_cpu.parquet"
    assert "audit: agrees with the CPU reference" in capsys.readouterr().out


def test_a_cpu_sweep_has_no_audit_and_bad_fractions_are_one_line(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", "--seeds", "4", "--backend", "cpu", "--out", str(out), "--no-rerun", "--no-progress"]) == 0
    assert "audit" not in json.loads((out / "summary.json").read_text())
    capsys.readouterr()
    assert main(["sweep", "--audit", "2", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert "fraction" in err and len(err.splitlines()) == 1
