"""Training with physics randomised per episode: `train --randomize` rolls DAgger's episodes out and judges
its held-out seeds at each seed's drawn physics, and `eval --randomize` judges a trained policy at a range's end."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers import cli, over, train_run

pytest.importorskip("flax")
pytest.importorskip("optax")

from mjx_pusht.model.params import ParamError  # noqa: E402
from mjx_pusht.model.randomize import factors  # noqa: E402
from mjx_pusht.train.dagger import DaggerConfig  # noqa: E402

RZ = "tee_mass=0.5:2,kv=0.8:1.2"
TINY = ("--backend", "cpu", "--reset", "chapter", "--envs", "8", "--iterations", "1", "--fit-steps", "20",
        "--batch", "64", "--hidden", "16,16", "--eval-envs", "6", "--max-samples", "5000", "--max-steps", "60",
        "--no-rerun", "--record", "0", "--no-progress")
MASS, KV = 0.105, 20.0  # the chapter's own tee mass (kg) and servo kv, which the factors scale


def _table(folder):
    return pq.read_table(folder / "per_episode.parquet").to_pydict()


@pytest.mark.slow
def test_a_dagger_run_with_randomize_judges_its_held_out_seeds_at_their_drawn_physics(tmp_path_factory, tmp_path):
    run = train_run(tmp_path_factory, *TINY, "--randomize", RZ)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["held_out"]["randomize"] == [["kv", [0.8, 1.2]], ["tee_mass", [0.5, 2.0]]]
    rows = _table(run / "eval")
    seeds = np.asarray(rows["seed"])
    f = factors((("kv", (0.8, 1.2)), ("tee_mass", (0.5, 2.0))), seeds)  # model/randomize's draw of each seed
    np.testing.assert_allclose(rows["param_kv"], f[:, 0] * KV, rtol=1e-12)
    np.testing.assert_allclose(rows["param_tee_mass"], f[:, 1] * MASS, rtol=1e-12)
    # The trainer's own last judgement (its rollout of the held-out rows) is eval's at the drawn physics, to the bit
    assert summary["curve"][-1]["coverage"] == np.mean(rows["final_coverage"])
    policy = f"policy:{run / 'policy.msgpack'}"
    common = ("--seeds", f"{seeds[0]}:{seeds[-1] + 1}", "--backend", "cpu", "--controller", policy, "--reset",
              "chapter", "--max-steps", "60", "--no-rerun", "--record", "0", "--no-progress")
    # a range's end (lo = hi): every episode at twice the mass, the robustness table's column
    r = cli("eval", *common, "--randomize", "tee_mass=2:2", "--out", str(tmp_path / "heavy"))
    assert r.returncode == 0, r.stderr
    assert _table(tmp_path / "heavy")["param_tee_mass"] == [2 * MASS] * len(seeds)
    # --resume compares the ranges as it compares every setting
    args = list(TINY)
    r = cli("train", *args, "--randomize", "tee_mass=0.5:1", "--out", str(run), "--resume")
    assert r.returncode == 1 and "other settings (randomize)" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_daggers_rollouts_step_each_seeds_drawn_physics_as_eval_does():
    """The teacher driving (iteration 0, the expert's share 1) on DAgger's env: each episode ends where eval's expert
    ends it at that seed's drawn physics, to the bit, and elsewhere than at the scene's own physics (the block is
    pushed: the physics shows). The held-out rows ride in the same rollouts, so they step the same worlds."""
    from mjx_pusht.backends.cpu import run_cpu
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.controllers import Expert
    from mjx_pusht.task.episode import Episode
    from mjx_pusht.train.dagger import Rollouts
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.run import dagger_env

    rz, seeds = {"tee_mass": (0.5, 2.0), "kv": (0.8, 1.2)}, np.arange(4)
    coverage = {}
    for name, r in (("drawn", rz), ("own", None)):
        cfg = DaggerConfig(envs=4, hidden=(8,), teacher="expert", reset="chapter", max_steps=80, randomize=r)
        unit = (np.zeros(cfg.sample_width, np.float32), np.ones(cfg.sample_width, np.float32))
        _, _, outcome = Rollouts(dagger_env(cfg, "cpu"), cfg)(Learner(cfg).params, unit, seeds, 1.0, 0)
        coverage[name] = outcome["coverage"]
    expert = Scenario(reset="chapter", controller=Expert(), episode=Episode(max_steps=80), randomize=rz)
    np.testing.assert_array_equal(coverage["drawn"], run_cpu(expert, seeds).columns()["task_coverage"])
    assert (coverage["drawn"] != coverage["own"]).all()


def test_train_randomize_is_checked_before_anything_runs():
    assert DaggerConfig().randomize is None  # nothing asked for: the config (and a resume file's) as before
    assert DaggerConfig(randomize={"tee_mass": (0.5, 2)}).randomize == (("tee_mass", (0.5, 2.0)),)
    with pytest.raises(ParamError, match="inverted"):
        DaggerConfig(randomize={"tee_mass": (2.0, 1.0)})
    with pytest.raises(ParamError, match="means nothing on the gym-pusht task"):
        DaggerConfig(task="gym-pusht", teacher="expert", randomize={"tee_mass": (0.5, 2.0)})


@pytest.mark.parametrize("args, says", [(("--randomize", "tee_mass=2:1"), "inverted"),
                                        (("--algo", "ppo", "--backend", "mjx-jax", "--randomize", "kp=0.5:2"),
                                         "kp means nothing on the chapter task")])
def test_bad_train_randomize_is_one_line_and_writes_nothing(tmp_path, args, says):
    r = cli("train", *over(("--backend", "cpu", "--no-rerun"), *args, "--out", str(tmp_path / "out")))
    assert r.returncode != 0 and says in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "out").exists()
