"""Controllers: the expert solves the task, zero and random do not, random is the same in NumPy and JAX."""

from __future__ import annotations

import os

import numpy as np
import pytest
from helpers import ENV, EPISODE, cli

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.io.outputs import read_table
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.controllers import (
    Expert,
    Random,
    Zero,
    seed_key,
    uniform_hash,
)
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.reset import start_poses
from mjx_pusht.task.rules import SUCCESS_COVERAGE, coverage


@pytest.fixture(scope="session")
def expert_cpu():
    """The expert on the CPU reference: task seeds 0..15 and chapter seeds 0..7."""
    return {
        reset: run_cpu(Scenario(reset=reset, controller=Expert(), episode=EPISODE), np.arange(n))
        for reset, n in (("task", 16), ("chapter", 8))
    }


# --- the expert ---------------------------------------------------------------------------------


def test_expert_solves_every_chapter_start(expert_cpu):
    r = expert_cpu["chapter"]
    assert r.episode["success"].all()
    assert (r.episode["coverage"] >= SUCCESS_COVERAGE).all()
    # the episode's end pose is the one that was scored, and it scores as covered
    np.testing.assert_allclose(coverage(r.final), r.episode["coverage"], atol=1e-12)


def test_expert_solves_random_task_starts_and_keeps_the_t_rigid(expert_cpu):
    r = expert_cpu["task"]
    assert r.episode["success"].mean() >= 15 / 16
    ok = r.episode["success"]
    assert (r.episode["steps_to_success"][ok] >= 1).all() and (r.episode["steps_to_success"][ok] <= 300).all()
    assert r.rigid.all() and r.finite.all() and r.contained.all()
    # it moved the T: task starts lie anywhere in the workspace, far from the target
    assert np.median(np.hypot(r.start[:, 0], r.start[:, 1])) > 0.1


def test_zero_succeeds_only_where_the_start_is_already_covered():
    seeds = np.arange(24)
    r = run_cpu(Scenario(reset="task", controller=Zero(), episode=Episode(max_steps=20)), seeds)
    starts = start_poses(seeds, reset="task")
    np.testing.assert_array_equal(r.episode["success"], coverage(starts[:, :3]) >= SUCCESS_COVERAGE)
    np.testing.assert_allclose(r.final, r.start, atol=1e-9)  # nothing touches the T: it does not move


def test_random_pushing_does_not_solve_the_task():
    r = run_cpu(Scenario(reset="task", controller=Random(), episode=Episode(max_steps=100)), np.arange(16))
    assert r.episode["success"].sum() == 0
    assert r.finite.all() and r.contained.all()


def test_random_is_seeded_and_the_same_in_numpy_and_jax():
    import jax.numpy as jnp

    key = seed_key(np.array([0, 1, 2**40 + 3, 2**63 - 1]))
    a = uniform_hash(key, 7, 0)
    b = np.asarray(uniform_hash(jnp.asarray(key), jnp.int32(7), 0))
    np.testing.assert_array_equal(a, b)
    assert len(set(a.tolist())) == 4 and (a >= 0).all() and (a < 1).all()
    assert not np.array_equal(uniform_hash(key, 8, 0), a)


# --- the environment API ------------------------------------------------------------------------


def test_a_users_controller_by_dotted_path_and_bad_controllers_fail_in_one_line(tmp_path):
    (tmp_path / "my_policy.py").write_text(
        "def hold(obs, t):\n    return obs['state'][..., 0:2] * 0.0\n"
        "def wrong(obs, t):\n    return obs['state']\n")
    (tmp_path / "broken_policy.py").write_text("import nonexistent_package_xyz\n")
    env = {**ENV, "PYTHONPATH": str(tmp_path) + os.pathsep + ENV.get("PYTHONPATH", "")}
    base = ["eval", "--seeds", "2", "--backend", "cpu", "--max-steps", "3", "--no-rerun", "--no-progress"]
    ok = cli(*base, "--controller", "my_policy:hold", "--out", str(tmp_path / "ok"), env=env)
    assert ok.returncode == 0, ok.stderr
    assert read_table(tmp_path / "ok" / "per_episode.parquet")["episode_length"].tolist() == [3, 3]
    for spec, words in (("teleport", "unknown controller"), ("broken_policy:hold", "cannot import"),
                        ("my_policy:missing", "no function"), ("my_policy:wrong", "shape")):
        r = cli(*base, "--controller", spec, "--out", str(tmp_path / "bad"), env=env)
        assert r.returncode != 0 and words in r.stderr, (spec, r.stderr)
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
