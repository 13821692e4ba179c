"""The tenth hostile pass's findings, each run again as written (docs/notebook/hostile10.md; what changed for each:
docs/notebook/boundary.md, "After the tenth pass")."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from fuzzing import snapshot
from helpers import RUNS, one_line, over

from mjx_pusht.cli import main
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.wrappers import AutoReset
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

POLICY = Path(__file__).parent.parent / "outputs/reports/train/ppo-state-gym-pusht-h200/seed-0/policy.msgpack"

# A user's controllers: one that raises (its message holds "boom", which the chunk retry took for "oom"), and one
# that fails from its third call on, so that an eval in chunks of one episode finishes two chunks first
CONTROLLERS = """
import os
import numpy as np
CALLS = os.path.join(os.path.dirname(__file__), "calls")  # counted in a file: eval's episodes run in processes
def raises(obs, t): raise RuntimeError("boom from user")
def good(obs, t): return np.zeros(obs["state"].shape[:-1] + (2,))
def third_fails(obs, t):
    with open(CALLS, "a") as f:
        f.write(".")
    if os.path.getsize(CALLS) > 2 * 2:  # two episodes of two steps, then the third fails
        raise RuntimeError("third episode")
    return np.zeros(obs["state"].shape[:-1] + (2,))
"""


@pytest.fixture
def controllers(tmp_path, monkeypatch):
    (tmp_path / "ctl10.py").write_text(CONTROLLERS)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    sys.modules.pop("ctl10", None)


def test_a_replacement_that_fails_puts_the_earlier_results_back(tmp_path, capsys, controllers):
    """LOST (tenth pass): `eval --replace` whose controller raised left only `.run.json`: the earlier table and
    summary were gone. They are set aside until the run finishes, and put back when it fails; the controller's own
    "boom" is said once, not retried seven times as out of memory."""
    out = tmp_path / "e"
    assert main([*RUNS["eval"], "--out", str(out)]) == 0
    before = snapshot(out)
    capsys.readouterr()
    assert main([*RUNS["eval"], "--out", str(out), "--replace", "--controller", "ctl10:raises"]) == 1
    captured = capsys.readouterr()
    assert "out of memory" not in captured.out, captured.out
    assert "are back as they were" in captured.out
    assert captured.err.strip().splitlines() == ["mjx-pusht: error: controller ctl10:raises raised RuntimeError: "
                                                 "boom from user"]
    assert snapshot(out) == before
    # and a replacement that finishes replaces them, leaving nothing aside
    assert main([*RUNS["eval"], "--out", str(out), "--replace", "--controller", "ctl10:good"]) == 0
    assert not (out / ".replaced").exists() and snapshot(out) != before


def test_a_replacement_that_kept_chunks_keeps_the_earlier_results_aside_until_one_finishes(tmp_path, capsys,
                                                                                          controllers):
    """An interrupted or failed replacement that kept chunks to resume leaves the earlier results in `.replaced/`
    (not lost, not mixed in); the resumed run that finishes removes them."""
    out = tmp_path / "e"
    assert main([*RUNS["eval"], "--out", str(out)]) == 0
    earlier = snapshot(out)
    flags = ["eval", "--backend", "cpu", "--seeds", "4", "--max-steps", "2", "--chunk", "1", "--no-rerun",
             "--no-progress", "--controller", "ctl10:third_fails", "--out", str(out)]
    assert main([*flags, "--replace"]) == 1
    assert "wait in" in capsys.readouterr().out
    aside = snapshot(out / ".replaced")
    assert {k: v for k, v in earlier.items() if k != ".run.json"}.items() <= aside.items()
    (tmp_path / "calls").write_text("")  # the controller fixed: its next two episodes run
    assert main([*flags, "--resume"]) == 0
    assert not (out / ".replaced").exists()


def test_an_evals_video_inside_its_own_folder_can_be_rerun(tmp_path, capsys):
    """REFUSED (tenth pass): an eval's --video inside its --out could not be rerun, --replace or not: the folder
    "held files eval did not write (v.gif)". It is the eval's own, by its summary's record of it."""
    out = tmp_path / "e"
    video = ["--video", str(out / "v.gif"), "--video-size", "32"]
    assert main([*RUNS["eval"], "--out", str(out), *video]) == 0
    assert main(over(RUNS["eval"], "--out", str(out), *video, "--replace", "--seeds", "3")) == 0
    capsys.readouterr()
    assert main(over(RUNS["eval"], "--out", str(out), *video, "--seeds", "3")) == 1
    one_line(capsys, "already exists", "pass --replace")


def test_the_hint_to_pass_replace_is_given_only_where_it_would_work(tmp_path, capsys):
    """SURPRISE (tenth pass): a user's file as --video was refused with "pass --replace to overwrite it", and then
    refused again with --replace. Now the one line says why it never is."""
    picture = tmp_path / "mine.gif"
    picture.write_bytes(b"GIF89a a user's")
    for extra in ([], ["--replace"]):
        assert main([*RUNS["eval"], "--out", str(tmp_path / "e"), "--video", str(picture), *extra]) == 1
        assert "--replace" not in one_line(capsys, "no earlier eval", "never overwritten")


def test_a_range_reaches_the_last_seed(tmp_path, capsys):
    """REFUSED (tenth pass): `--seeds 2**63-2:2**63` (its seeds 2**63-2 and 2**63-1, both legal) was refused as
    "got 9223372036854775808". A range's end is past its last seed."""
    out = tmp_path / "e"
    assert main(over(RUNS["eval"], "--seeds", f"{2**63 - 2}:{2**63}", "--out", str(out))) == 0
    import pyarrow.parquet as pq

    assert pq.read_table(out / "per_episode.parquet").column("seed").to_pylist() == [2**63 - 2, 2**63 - 1]
    capsys.readouterr()
    assert main(over(RUNS["eval"], "--seeds", f"0:{2**63 + 1}", "--out", str(tmp_path / "f"))) == 1
    one_line(capsys, "got 9223372036854775809")


def test_a_compile_cache_that_cannot_be_made_is_one_line(tmp_path, capsys, monkeypatch):
    """TRACEBACK (tenth pass): MJX_PUSHT_JAX_CACHE=/proc/nope, a folder that cannot be made: FileNotFoundError."""
    monkeypatch.setenv("MJX_PUSHT_JAX_CACHE", "/proc/nope/cache")
    out = tmp_path / "e"
    assert main(["eval", "--backend", "mjx-jax", "--seeds", "2", "--max-steps", "2", "--no-progress", "--no-rerun",
                 "--out", str(out)]) == 1
    one_line(capsys, "MJX_PUSHT_JAX_CACHE=/proc/nope/cache", "cannot make the folder")
    assert not out.exists()


def test_a_functional_env_takes_only_its_own_tasks_states():
    """SILENT (tenth pass): a chapter env stepped a gym-pusht env's State without a word (its values in the wrong
    frame, reward 0); reset_where of something else than a State was an AttributeError."""
    chapter, gym_pusht = PushTEnv(backend="cpu"), PushTEnv.for_task("gym-pusht")
    for env, other in ((chapter, gym_pusht), (gym_pusht, chapter)):
        state = other.reset(np.arange(2))
        with pytest.raises(MjxPushtError, match="came from an env of another scene, task, goal"):
            env.step(state, np.zeros((2, 2)))
        with pytest.raises(MjxPushtError, match="came from an env of another scene, task, goal"):
            env.reset_where(state, np.array([True, False]), np.arange(1))
        assert np.isfinite(other.step(state, np.zeros((2, 2))).reward).all()  # its own env steps it
    with pytest.raises(MjxPushtError, match="reset_where takes the State that reset or step returned, got None"):
        chapter.reset_where(None, np.array([True]), np.arange(1))


def test_final_pixels_needs_pixels():
    """SILENT (tenth pass): AutoReset(env, final_pixels=True) on an env that draws no image was taken."""
    with pytest.raises(MjxPushtError, match="draws none"):
        AutoReset(PushTEnv(backend="cpu"), final_pixels=True)


def test_a_gym_pusht_policys_seed_is_an_integer():
    """TRACEBACK (tenth pass): GymPushtPolicy(path, seed=None) was numpy's TypeError."""
    with pytest.raises(MjxPushtError, match="got None"):
        GymPushtPolicy(POLICY, seed=None)


def test_brax_envs_keywords_are_bound():
    """TRACEBACK (tenth pass): BraxPushT(bogus=1) was Python's TypeError."""
    pytest.importorskip("brax")
    from mjx_pusht.envs.brax import BraxPushT

    with pytest.raises(MjxPushtError, match="unexpected keyword argument 'bogus'; it takes backend"):
        BraxPushT(bogus=1)
