"""benchmarks.env_loop's `scan_autoreset` and `*_ends` cases: episodes short enough that every row ends and restarts
within the timed steps, and the count of those ends reported beside the rate (the plain gym cases' 300-step episodes
never end)."""

from __future__ import annotations

import json

import pytest


@pytest.mark.slow
@pytest.mark.warp
def test_the_ends_cases_reset_every_row_each_episode_and_count_it(tmp_path):
    from benchmarks import env_loop

    out = tmp_path / "loop.json"
    n, steps, ends = 4, 4, 2
    assert env_loop.main(["--envs", str(n), "--steps", str(steps), "--ends", str(ends), "--json", str(out),
                          "--cases", "scan_autoreset,dropin_numpy_ends"]) == 0
    row = json.loads(out.read_text())["runs"][0]["rows"][0]
    assert "error" not in json.dumps(row), row
    # every row ends each `ends` steps: steps / ends resets a row, in the timed steps alone
    assert row["scan_autoreset"]["episodes_reset"] == n * steps // ends
    assert row["dropin_numpy_ends"]["episodes_reset"] == n * steps // ends
    assert row["scan_autoreset"]["compiles"] == 1 and row["scan_autoreset"]["control_steps_per_s"] > 0
