"""The eleventh hostile pass's findings, each run again as written (docs/notebook/hostile11.md; what changed for each:
docs/notebook/boundary.md, "After the eleventh pass")."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from fuzzing import snapshot
from helpers import RUNS, one_line, over

import mjx_pusht  # noqa: F401 - registers the gym ids
from mjx_pusht import SceneSpec
from mjx_pusht.cli import main
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.task.episode import Episode


def test_train_with_random_goals_runs_on_the_cpu(tmp_path, capsys):
    """REFUSED (eleventh pass; the tenth pass's fix broke it): `train --goal random` on the cpu backend stopped at its
    first step, "the State came from an env of another task or goal": the env's goal is its episode's."""
    out = tmp_path / "t"
    assert main([*RUNS["train"], "--goal", "random", "--max-steps", "5", "--out", str(out)]) == 0, \
        capsys.readouterr().err
    assert (out / "policy.msgpack").is_file()


@pytest.mark.parametrize("command,name", [("eval", "per_episode.parquet"), ("sweep", "per_seed.parquet"),
                                          ("scene", "metrics.json"), ("train", "policy.msgpack")])
@pytest.mark.parametrize("share", [[], ["--share-out"]])
def test_a_users_file_named_as_a_result_is_never_taken_for_one(tmp_path, capsys, command, name, share):
    """LOST (eleventh pass): a user's lone `per_episode.parquet` (or per_seed.parquet, metrics.json, policy.msgpack)
    was taken for a finished run of the command, from before run files existed, and overwritten. A result with no
    run file beside it is nobody's: refused, whatever the flags."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / name).write_text("a user's own file")
    before = snapshot(out)
    assert main([*RUNS[command], "--out", str(out), *share]) == 1
    one_line(capsys, "holds files no mjx-pusht run wrote here", name)
    assert snapshot(out) == before


def test_a_users_file_in_the_replaced_folder_is_never_removed(tmp_path, capsys):
    """LOST (eleventh pass): a finishing `--replace` removed the whole `.replaced/`, a user's file in it too. The
    folder's own strays rule covers it: refused without --share-out; with it, the user's file stays."""
    out = tmp_path / "e"
    assert main([*RUNS["eval"], "--out", str(out)]) == 0
    (out / ".replaced").mkdir()
    (out / ".replaced" / "mine.txt").write_text("mine")
    capsys.readouterr()
    assert main(over(RUNS["eval"], "--seeds", "3", "--out", str(out), "--replace")) == 1
    one_line(capsys, ".replaced/mine.txt", "--share-out")
    assert main(over(RUNS["eval"], "--seeds", "3", "--out", str(out), "--replace", "--share-out")) == 0
    assert (out / ".replaced" / "mine.txt").read_text() == "mine"
    assert sorted(p.name for p in (out / ".replaced").iterdir()) == ["mine.txt"]  # the earlier results went


def test_randomize_given_twice_is_refused(tmp_path, capsys):
    """SILENT (eleventh pass): a second --randomize replaced the first without a word."""
    assert main([*RUNS["sweep"], "--randomize", "tee_mass=0.5:2", "--randomize", "kv=0.9:1.1",
                 "--out", str(tmp_path / "s")]) == 2
    one_line(capsys, "--randomize", "given twice")
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("made,stepped", [
    (dict(scene=SceneSpec(break_it="split-tee")), dict()),  # a raw ValueError, "zero-size array"
    (dict(), dict(scene=SceneSpec(break_it="split-tee"))),  # the pusher at (0, 0), without a word
    (dict(scene=SceneSpec(pusher="capsule")), dict()),
    (dict(), dict(randomize={"kv": (0.5, 0.6)})),  # the drawn physics not applied
    (dict(randomize={"kv": (0.5, 0.6)}), dict()),
])
def test_a_functional_env_takes_only_its_own_scenes_and_physics_states(made, stepped):
    """SILENT and TRACEBACK (eleventh pass): a State of another scene or of other physics, stepped."""
    state = PushTEnv(**made).reset(np.arange(2))
    with pytest.raises(MjxPushtError, match="came from an env of another scene, task, goal or physics"):
        PushTEnv(**stepped).step(state, np.full((2, 2), 0.5))


def test_episode_binds_and_checks_its_fields():
    """TRACEBACK (eleventh pass): Episode(foo=1) was Python's TypeError; Episode(goal='x') failed at the first step."""
    with pytest.raises(MjxPushtError, match="unexpected keyword argument 'foo'"):
        Episode(foo=1)
    with pytest.raises(MjxPushtError, match="goal region"):
        Episode(goal="x")


@pytest.mark.parametrize("call", [
    lambda: gym.make_vec("mjx_pusht/PushT-v0", num_envs=2).reset(foo=1),
    lambda: gym.make("mjx_pusht/PushT-v0").unwrapped.reset(foo=1),
    lambda: gym.make("mjx_pusht/PushT-gym-pusht-v0").unwrapped.render(1),
])
def test_the_gym_envs_bind_their_arguments(call):
    """TRACEBACK (eleventh pass): an unknown keyword to reset or render was Python's TypeError."""
    with pytest.raises(MjxPushtError, match="it takes"):
        call()


def test_a_vector_envs_call_of_step_without_actions_is_one_line():
    v = gym.make_vec("mjx_pusht/PushT-v0", num_envs=3)
    v.reset(seed=0)
    with pytest.raises(MjxPushtError, match="missing a required argument: 'actions'"):
        v.call("step")


def test_brax_reset_takes_a_key():
    """TRACEBACK (eleventh pass): BraxPushT().reset('x') was JAX's own TypeError on key data."""
    pytest.importorskip("brax")
    from mjx_pusht.envs.brax import BraxPushT

    with pytest.raises(MjxPushtError, match="takes a JAX random key"):
        BraxPushT(backend="mjx-jax", max_worlds=4, table=2).reset("x")
