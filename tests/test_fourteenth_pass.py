"""The fourteenth hostile pass's findings, each run again as written (docs/notebook/hostile14.md; the rest are in
docs/notebook/boundary.md, "After the fourteenth pass")."""

from __future__ import annotations

from helpers import one_line

from mjx_pusht.cli import main


def test_compare_welded_with_no_rerun_is_refused_and_writes_nothing(tmp_path, capsys):
    """SILENT (fourteenth pass): `scene --compare-welded --break split-tee --no-rerun` wrote walk.rrd, a recording
    --no-rerun says to skip, without a word. Its one output is that recording: the two are refused together."""
    argv = ["scene", "--compare-welded", "--break", "split-tee", "--steps", "5", "--out", str(tmp_path / "o")]
    assert main([*argv, "--no-rerun"]) == 2
    one_line(capsys, "--compare-welded records", "--no-rerun skips")
    assert not (tmp_path / "o").exists()
    assert main(argv) == 0  # with its recording: both runs, side by side
    assert (tmp_path / "o" / "walk.rrd").stat().st_size > 1000


def test_an_interrupted_evals_chunks_are_called_an_evals(tmp_path, monkeypatch, capsys):
    """SURPRISE (fourteenth pass), a wrong word: rerun without --resume after an interrupted eval, the refusal called
    its chunks "an unfinished sweep"."""
    import mjx_pusht.study.sweep as sweep_module

    real = sweep_module.run_sweep

    def cut(backend, seeds, out, **kw):  # the real eval over its first seed, then the interrupt
        real(backend, seeds[:1], out, **kw)
        raise KeyboardInterrupt

    argv = ["eval", "--backend", "cpu", "--seeds", "3", "--max-steps", "2", "--chunk", "1", "--no-rerun",
            "--no-progress", "--out", str(tmp_path / "o")]
    monkeypatch.setattr(sweep_module, "run_sweep", cut)
    assert main(argv) == 130
    monkeypatch.setattr(sweep_module, "run_sweep", real)
    capsys.readouterr()
    assert main(argv) == 1
    one_line(capsys, "holds an unfinished eval (1 seeds done)", "--resume")


def test_a_float_image_is_refused_by_what_it_must_be():
    """SURPRISE (thirteenth and fourteenth passes), a wrong word: a float32 image handed to GymPushtPolicy was
    refused as "must be real numbers, got float32"; it must be uint8, and the line says so."""
    from pathlib import Path

    import numpy as np
    import pytest

    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy
    from mjx_pusht.errors import ConfigError

    path = Path(__file__).parents[1] / "outputs/reports/train/dagger-pixels-gym-pusht-h200-16k/seed-0/policy.msgpack"
    policy = GymPushtPolicy(path)
    with pytest.raises(ConfigError, match=r"observation\['pixels'\] must be unsigned integers \(uint8 for an image\)"):
        policy({"pixels": np.zeros((96, 96, 3), np.float32), "agent_pos": np.zeros(2)})
    assert policy({"pixels": np.zeros((96, 96, 3), np.uint8), "agent_pos": np.full(2, 256.0)}).shape == (2,)
