"""The thirteenth hostile pass's findings that are fixed, each run again as written (docs/notebook/hostile13.md; the
rest are in docs/notebook/boundary.md, "After the thirteenth pass")."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import one_line

from mjx_pusht.cli import main
from mjx_pusht.io.outputs import read_table


@pytest.mark.parametrize("frame_skip", [1, 3])
def test_an_eval_recording_has_one_reward_point_per_control_step_at_any_frame_skip(tmp_path, frame_skip):
    """TRACEBACK (thirteenth pass): `eval --frame-skip 1` wrote its recording's reward series one control step too
    long and ended in numpy's IndexError. Each episode's series is now its control steps, each at the frame that
    ends it, and its last point is the table's final coverage."""
    from rerun.chunk import RrdReader

    out = tmp_path / "e"
    assert main(["eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "5", "--frame-skip", str(frame_skip),
                 "--no-progress", "--record", "2", "--out", str(out)]) == 0
    table = read_table(out / "per_episode.parquet")
    rows = {str(c.entity_path): c.to_record_batch().to_pydict() for c in RrdReader(str(out / "eval.rrd")).stream()
            if "/plots/reward/" in str(c.entity_path)}
    for k, seed in enumerate(table["seed"]):
        r = rows[f"/plots/reward/seed_{seed}"]
        steps = int(table["episode_length"][k])
        assert len(r["sim_time"]) == steps == 5
        dt = r["sim_time"][0].total_seconds() / frame_skip  # the first point ends the first control step
        assert [t.total_seconds() for t in r["sim_time"]] == pytest.approx(np.arange(1, steps + 1) * frame_skip * dt)
        assert r["Scalars:scalars"][-1][0] == pytest.approx(table["final_coverage"][k], abs=1e-6)


@pytest.mark.parametrize("argv, flag", [
    (["eval", "--seeds", "2", "--seeds", "3"], "--seeds"),
    (["eval", "--seeds", "2", "--se", "3"], "--seeds"),  # argparse's prefix of the same flag
    (["sweep", "--backend", "cpu", "--backend", "mjx-jax"], "--backend"),
    (["eval", "--no-rerun", "--no-rerun"], "--no-rerun"),
    (["train", "--randomize", "kv=0.9:1.1", "--randomize", "kv=1:1"], "--randomize"),
])
def test_a_flag_given_twice_is_refused_and_writes_nothing(argv, flag, tmp_path, capsys):
    """SILENT (thirteenth pass): `eval --seeds 2 --seeds 3` ran seeds 0-2, the first value dropped without a word
    (argparse's last-wins). Each flag is taken once; --param, whose repeats are its meaning, still sweeps both."""
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    one_line(capsys, f"argument {flag}", "given twice")
    assert not (tmp_path / "o").exists()
    assert main(["eval", "--backend", "cpu", "--seeds", "1", "--max-steps", "2", "--no-rerun", "--no-progress",
                 "--param", "kv=10", "--param", "tee_mass=0.5", "--out", str(tmp_path / "p")]) == 0
    table = read_table(tmp_path / "p" / "per_episode.parquet")
    assert table["param_kv"].tolist() == [10.0] and table["param_tee_mass"].tolist() == [0.5]
