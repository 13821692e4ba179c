"""lerobot 0.6.1's own `lerobot-eval`, unchanged, on mjx_pusht: a small policy on the plugin's env (the batch on
MJX-Warp, and LeRobot's usual vector env of MuJoCo C envs), and `mjx-pusht demos` output, whose files LeRobot's own
writer would lay out alike. lerobot-train on the demos, and lerobot-eval on gym-pusht itself:
test_lerobot_diffusion.py."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from conftest import lerobot_eval


@pytest.mark.slow
@pytest.mark.warp
def test_lerobot_eval_on_the_plugins_batch_scores_as_on_its_per_env_vector_env(tiny_policy, tmp_path):
    """The same policy and seeds through lerobot-eval: the batch on MJX-Warp (float32) and LeRobot's defaults on
    a machine without a GPU (AsyncVectorEnv workers of MuJoCo C envs, float64) give the same episodes."""
    small = ("--env.type=mjx_pusht", "--env.observation_height=96", "--env.observation_width=96")
    batch = lerobot_eval(tiny_policy, tmp_path / "mjx", *small, "--env.backend=mjx-warp")
    per_env = lerobot_eval(tiny_policy, tmp_path / "mjx_cpu", *small, "--env.backend=cpu")
    for info in (batch, per_env):
        assert list(info["per_group"]) == ["mjx_pusht"]
    (b,), (c,) = batch["per_task"], per_env["per_task"]
    assert b["metrics"]["successes"] == c["metrics"]["successes"]
    assert np.allclose(b["metrics"]["sum_rewards"], c["metrics"]["sum_rewards"], rtol=1e-3, atol=1e-4)


def test_lerobot_reads_the_demos_as_its_own_writer_would_write_them(demos, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ours = LeRobotDataset("local/mjx_pusht_demos", root=demos)
    table = pq.read_table(sorted(demos.glob("data/*/*.parquet"))[0])
    assert ours.num_episodes == 2 and ours.num_frames == table.num_rows and ours.fps == 10
    last = ours[ours.num_frames - 1]
    assert bool(last["next.done"]) and int(last["episode_index"]) == 1
    row = table.slice(5, 1).to_pylist()[0]
    frame = ours[5]
    assert np.array_equal(frame["observation.state"].numpy(), np.float32(row["observation.state"]))
    assert np.array_equal(frame["action"].numpy(), np.float32(row["action"]))
    assert frame["task"] == "Push the T-shaped block onto the T-shaped target."
    # LeRobot's own writer, given the same features and one frame of ours, writes the same schema
    info = json.loads((demos / "meta/info.json").read_text())
    features = {k: v for k, v in info["features"].items()
                if k not in ("timestamp", "frame_index", "episode_index", "index", "task_index")}
    theirs = LeRobotDataset.create("local/theirs", fps=10, features=features, root=tmp_path / "theirs",
                                   use_videos=False)
    theirs.add_frame({k: (frame[k].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8) if k == "observation.image"
                      else np.atleast_1d(frame[k].numpy()) for k in features} | {"task": frame["task"]})
    theirs.save_episode()
    theirs.finalize()
    their_info = json.loads((tmp_path / "theirs/meta/info.json").read_text())
    assert their_info["features"] == info["features"]
    assert {k: their_info[k] for k in ("codebase_version", "data_path", "video_path", "chunks_size")} == \
        {k: info[k] for k in ("codebase_version", "data_path", "video_path", "chunks_size")}
    their_table = pq.read_table(sorted((tmp_path / "theirs").glob("data/*/*.parquet"))[0])
    assert their_table.schema.remove_metadata() == table.schema.remove_metadata()
    stats = json.loads((tmp_path / "theirs/meta/stats.json").read_text())
    assert set(stats) == set(json.loads((demos / "meta/stats.json").read_text()))
