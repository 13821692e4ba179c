"""The thirteenth hostile pass's findings that are fixed, each run again as written (docs/notebook/hostile13.md; the
rest are in docs/notebook/boundary.md, "After the thirteenth pass")."""

from __future__ import annotations

import json
import os

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


VIDEO = ["eval", "--backend", "cpu", "--max-steps", "5", "--no-progress", "--no-rerun"]


def test_an_evals_own_video_goes_with_its_results_under_replace_and_comes_back_if_the_run_fails(tmp_path, capsys,
                                                                                                 monkeypatch):
    """REFUSED (thirteenth pass): once an eval had drawn its video inside its --out, `--replace` without that same
    --video was refused, the video called a file "eval did not write". It is the eval's (reliability.md): a rerun
    of the same settings keeps it (and its stamp), --replace sets it aside with the results, a replacement that
    fails puts both back, and one that finishes removes it with the results it showed."""
    from fuzzing import snapshot

    out, gif = tmp_path / "own", tmp_path / "own" / "v.gif"
    assert main([*VIDEO, "--seeds", "2", "--out", str(out), "--video", str(gif), "--video-size", "32"]) == 0
    drawn = gif.read_bytes()
    assert main([*VIDEO, "--seeds", "2", "--out", str(out)]) == 0  # the same settings: the video still shows them
    summary = json.loads((out / "summary.json").read_text())
    assert summary["video"]["path"] == str(gif.resolve()) and gif.read_bytes() == drawn
    before = snapshot(out)
    (tmp_path / "ctl13.py").write_text("def raises(obs, t):\n    raise RuntimeError('boom')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    capsys.readouterr()
    assert main([*VIDEO, "--seeds", "4", "--out", str(out), "--replace", "--controller", "ctl13:raises"]) == 1
    assert snapshot(out) == before  # the failed replacement put the results and their video back as they were
    assert main([*VIDEO, "--seeds", "4", "--out", str(out), "--replace"]) == 0, capsys.readouterr().err
    assert sorted(os.listdir(out)) == [".run.json", "per_episode.parquet", "summary.json"]
    assert "video" not in json.loads((out / "summary.json").read_text())
    assert len(read_table(out / "per_episode.parquet")["seed"]) == 4


def test_a_recording_left_half_written_is_the_commands_own_leftover(tmp_path, capsys):
    """TRACEBACK (thirteenth pass), its second half: the failed recording left `.eval.rrd.partial`, and every
    rerun into the folder was then refused for it ("files eval did not write"). A failed recording removes it; one
    a kill left behind is the command's own leftover, and the rerun writes the recording whole."""
    out = tmp_path / "e"
    args = ["eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-progress", "--record", "1",
            "--out", str(out)]
    assert main(args) == 0
    (out / ".eval.rrd.partial").write_bytes(b"half a recording, as a kill leaves it")
    assert main(args) == 0, capsys.readouterr().err
    assert not (out / ".eval.rrd.partial").exists() and (out / "eval.rrd").stat().st_size > 1000


def test_the_functional_envs_step_checks_its_keywords_on_mjx_as_on_cpu():
    """TRACEBACK (thirteenth pass): on mjx-jax `step(state, a, bogus=1)`, `step(state)` and a third positional were
    Python's TypeError (the MJX env's step was an instance's own function, past the class's keyword check)."""
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.api import KeywordError

    for backend in ("cpu", "mjx-jax"):
        env = PushTEnv(backend=backend)
        state, a = env.reset(np.arange(2)), np.zeros((2, 2), np.float32)
        for call in (lambda: env.step(state, a, bogus=1), lambda: env.step(state), lambda: env.step(state, a, a)):
            with pytest.raises(KeywordError, match=r"PushTEnv.step\(\) .*it takes state, action"):
                call()


def test_autoreset_on_mjx_refuses_another_tasks_state_and_never_steps_a_nan_as_zero():
    """TRACEBACK and SILENT (thirteenth pass): AutoReset on mjx-jax stepped another task's State into JAX's
    scan-carry TypeError, and a NaN action as a zero one (finite, not broken). Now: the State is one line; a
    NaN from the host is refused at the step, as the env's own step refuses it; one already on the device (looked
    at there, never waited for) holds its row still, marks it broken, and the next refill says so."""
    import jax.numpy as jnp

    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.envs.wrappers import AutoReset
    from mjx_pusht.errors import ConfigError

    ar = AutoReset(PushTEnv(backend="mjx-jax"))
    state = ar.reset(np.arange(2))
    other = AutoReset(PushTEnv.for_task("gym-pusht", backend="mjx-jax")).reset(np.arange(2))
    with pytest.raises(ConfigError, match="State came from an env of another scene, task"):
        ar.step(other, np.zeros((2, 2), np.float32))
    with pytest.raises(ConfigError, match="actions must be finite"):
        ar.step(state, np.array([[0, 0], [np.nan, 0]], np.float32))
    still = ar.step(state, jnp.zeros((2, 2), jnp.float32))
    held = ar.step(state, jnp.array([[0, 0], [jnp.nan, 0]], jnp.float32))
    assert np.asarray(held.info["broken"]).tolist() == [False, True]
    np.testing.assert_array_equal(np.asarray(held.data.qpos), np.asarray(still.data.qpos))  # row 1 held as row 0 is
    with pytest.raises(ConfigError, match=r"rows \[1\] were given a non-finite action"):
        ar.refill(held)
    ar.refill(still)  # a clean state refills


def test_autoreset_refill_takes_only_its_own_envs_state():
    """SILENT (thirteenth pass): on cpu, AutoReset.refill took another task's State, which its step refused."""
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.envs.wrappers import AutoReset
    from mjx_pusht.errors import ConfigError

    ar = AutoReset(PushTEnv())
    ar.reset(np.arange(2))
    other = AutoReset(PushTEnv.for_task("gym-pusht")).reset(np.arange(2))
    with pytest.raises(ConfigError, match="AutoReset.refill.*|State came from an env of another scene"):
        ar.refill(other)


def test_gym_pushts_starts_in_its_walls_are_said_and_starts_beyond_its_window_refused():
    """SILENT (thirteenth pass): the drop-in took a T at (0, 0) px, in gym-pusht's walls, without a word (the first
    step flung it to (121, 52) px), and the functional env of gym-pusht's scene took a start metres away. The
    drop-in still takes what gym-pusht takes (its window), and says when a body is in the walls; the functional
    env refuses a body beyond the window."""
    import warnings

    import gymnasium as gym

    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.errors import ConfigError

    env = gym.make("mjx_pusht/PushT-gym-pusht-v0")
    for start, said in (([0.1, 0.1, 0, 0, 0], True), ([500, 500, 511.9, 511.9, 0], True),
                        ([256, 256, 300, 300, 1.0], False)):
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            obs, _ = env.reset(seed=0, options={"reset_to_state": start})
        assert any("in gym-pusht's walls" in str(x.message) for x in w) == said
        np.testing.assert_allclose(obs[:2], start[:2], atol=1e-9)  # taken, as gym-pusht takes it
    with pytest.raises(ConfigError, match="outside gym-pusht's 512-pixel window"):
        PushTEnv.for_task("gym-pusht").reset_to(np.array([[100, 100, 256, 256, 0.5]]))


def test_an_episode_of_more_physics_steps_than_a_rollout_runs_is_refused_before_anything(tmp_path, capsys):
    """HANG, by its brief's rule not counted (thirteenth pass): `--max-steps 100000 --frame-skip 1000`, each inside
    its own bound, made 10**8 physics steps an episode: hours a seed, and a recording's trace of 4 GB an episode.
    Their product is bounded too (10**6: what --max-steps 100,000 reaches at the default frame skip)."""
    from mjx_pusht import validate

    assert validate.MAX_PHYSICS_STEPS == validate.MAX_STEPS * 10
    argv = ["eval", "--backend", "cpu", "--seeds", "2", "--no-progress", "--out", str(tmp_path / "o")]
    assert main([*argv, "--max-steps", "100000", "--frame-skip", "1000"]) == 1
    one_line(capsys, "100,000,000 physics steps", "more than the 1,000,000 a rollout runs")
    assert not (tmp_path / "o").exists()
    assert main([*argv, "--max-steps", "1001", "--frame-skip", "1000"]) == 1  # one control step past the bound
    one_line(capsys, "1,001,000 physics steps")
