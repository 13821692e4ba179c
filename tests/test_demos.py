"""`mjx-pusht demos`: a controller's episodes written as a LeRobot dataset (v3.0 files, read here with pyarrow
and Pillow alone; tests/lerobot/ reads them with lerobot 0.6.1 itself and trains on them).

The written actions are gym-pusht's (absolute targets in pixels): replayed from each episode's seed in the
drop-in's single env (MuJoCo C, one env at a time, not the batch that wrote them), they reproduce every
recorded state, image, reward and ending.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pyarrow.parquet as pq
import pytest

import mjx_pusht  # noqa: F401  (registers the env ids)
from mjx_pusht.cli import main

STEPS = 40  # episodes truncated here: short, and the expert has turned and pushed by then


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("demos") / "ds"
    assert main(["demos", "--seeds", "5,9", "--backend", "cpu", "--max-steps", str(STEPS), "--out", str(out),
                 "--no-progress"]) == 0
    return out


def episodes(root: Path) -> list[dict]:
    table = pq.read_table(sorted((root / "data").glob("*/*.parquet"))[0]).to_pydict()
    eps: dict[int, dict] = {}
    for i, e in enumerate(table["episode_index"]):
        ep = eps.setdefault(e, {k: [] for k in table})
        for k in table:
            ep[k].append(table[k][i])
    return [eps[e] for e in sorted(eps)]


def decode(cell) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(cell["bytes"])))


def test_the_dataset_is_lerobots_v3_layout(demos):
    info = json.loads((demos / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == 10
    assert info["features"]["observation.image"]["shape"] == [96, 96, 3]
    assert info["total_episodes"] == 2
    eps = episodes(demos)
    assert info["total_frames"] == sum(len(e["index"]) for e in eps)
    meta = pq.read_table(demos / "meta/episodes/chunk-000/file-000.parquet").to_pydict()
    assert meta["length"] == [len(e["index"]) for e in eps]
    assert meta["dataset_from_index"] == [0, len(eps[0]["index"])]
    for e in eps:  # frame indices count from 0, timestamps at 10 fps, the last frame alone is done
        n = len(e["frame_index"])
        assert e["frame_index"] == list(range(n))
        assert np.allclose(e["timestamp"], np.arange(n) / 10)
        assert e["next.done"] == [False] * (n - 1) + [True]
    stats = json.loads((demos / "meta/stats.json").read_text())
    actions = np.array([a for e in eps for a in e["action"]])
    assert np.allclose(stats["action"]["mean"], actions.mean(0)) and stats["action"]["count"] == [len(actions)]
    # the image statistics: of every 10th frame of an episode (a sample, as LeRobot's own are)
    images = np.stack([decode(c) for e in eps for c in e["observation.image"][::10]]) / 255.0
    assert stats["observation.image"]["count"] == [len(images)]
    assert np.allclose(np.ravel(stats["observation.image"]["mean"]), images.mean((0, 1, 2)))
    assert np.allclose(np.ravel(stats["observation.image"]["std"]), images.std((0, 1, 2)))


def test_replaying_an_episodes_actions_in_the_drop_in_reproduces_its_states(demos):
    env = gym.make("mjx_pusht/PushT-gym-pusht-v0", obs_type="pixels_agent_pos", max_episode_steps=STEPS)
    for seed, ep in zip((5, 9), episodes(demos), strict=True):
        obs, _ = env.reset(seed=seed)
        n = len(ep["action"])
        for t in range(n):
            assert np.array_equal(np.float32(obs["agent_pos"]), np.float32(ep["observation.state"][t]))
            assert np.array_equal(obs["pixels"], decode(ep["observation.image"][t]))
            obs, reward, terminated, truncated, _ = env.step(np.asarray(ep["action"][t], np.float32))
            assert np.float32(reward) == np.float32(ep["next.reward"][t])
            assert terminated == ep["next.success"][t]
            assert (terminated or truncated) == ep["next.done"][t]
        assert terminated or n == STEPS
    # the actions are gym-pusht's: targets in its 512-pixel frame, moving the pusher about
    acts = np.array([a for e in episodes(demos) for a in e["action"]])
    assert acts.min() >= 0 and acts.max() <= 512 and np.ptp(acts, 0).min() > 50


def test_each_episodes_first_state_is_gym_pushts_own_observation_of_that_seed(demos):
    """observation.state is gym-pusht's `agent_pos`, as gym-pusht itself returns it at `reset(seed=...)`."""
    pytest.importorskip("gym_pusht")
    theirs = gym.make("gym_pusht/PushT-v0", obs_type="pixels_agent_pos")
    for seed, ep in zip((5, 9), episodes(demos), strict=True):
        obs, _ = theirs.reset(seed=seed)
        assert np.array_equal(np.float32(obs["agent_pos"]), np.float32(ep["observation.state"][0]))


def test_an_existing_dataset_is_kept_without_replace_and_bad_input_is_one_line(demos, capsys):
    # other seeds than the dataset's (the same ones rerun: test_fifth_pass.py)
    before = {p: p.read_bytes() for p in demos.rglob("*.parquet")}
    assert main(["demos", "--seeds", "1", "--backend", "cpu", "--out", str(demos)]) == 1
    assert "holds a LeRobot dataset; pass --replace" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in demos.rglob("*.parquet")} == before
    assert main(["demos", "--controller", "nope", "--out", str(demos.parent / "other")]) == 1
    assert not (demos.parent / "other").exists()


def test_successful_only_keeps_the_episodes_that_succeeded_and_counts_them_all(tmp_path):
    from mjx_pusht.io.demos import write_demos

    s = write_demos("expert", np.arange(8), tmp_path / "ds", backend="cpu", max_steps=90, successful_only=True,
                    progress=False)
    failed = set(s["failed_seeds"])
    assert 0 < len(failed) < 8  # at 90 steps the expert has finished some episodes and not others: both kinds ran
    eps = episodes(tmp_path / "ds")
    assert s["written"] == len(eps) == 8 - len(failed) and s["success_rate"] == len(eps) / 8
    assert all(e["next.success"][-1] and e["next.done"][-1] for e in eps)
    # the image statistics count the kept episodes' frames alone (every 10th)
    stats = json.loads((tmp_path / "ds" / "meta/stats.json").read_text())
    assert stats["observation.image"]["count"] == [sum(len(e["index"][::10]) for e in eps)]


def test_the_default_expert_solves_gym_pushts_task(tmp_path):
    from mjx_pusht.io.demos import write_demos

    s = write_demos("expert", np.arange(16), tmp_path / "ds", backend="cpu", progress=False)
    assert s["controller"].startswith("expert-gym-pusht") and s["success_rate"] >= 15 / 16, s["failed_seeds"]
