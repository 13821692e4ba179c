"""The fifth hostile pass's findings, each run again as written (docs/notebook/hostile5.md; what changed for each:
docs/notebook/boundary.md, "after the fifth pass")."""

from __future__ import annotations

import os
import time

import gymnasium as gym
import numpy as np
import pytest
from helpers import one_line

import mjx_pusht  # noqa: F401  (registers the gym ids)
from mjx_pusht.boundary import BYTES_PER_CPU_ENV, BYTES_PER_SEED, available_memory
from mjx_pusht.cli import main
from mjx_pusht.errors import ConfigError

EVAL = ["eval", "--backend", "cpu", "--max-steps", "2", "--seeds", "2", "--no-rerun", "--no-progress"]


def _over_memory(per: int) -> int:
    """A count whose estimate is past what this machine has available now (twice it)."""
    return 2 * available_memory() // per + 1


@pytest.mark.parametrize("command", ["eval", "sweep", "demos", "compare"])
def test_seeds_past_this_machines_memory_are_refused_at_once_and_write_nothing(command, tmp_path, capsys):
    n = _over_memory(BYTES_PER_SEED)  # 2**30, the count's own bound, was OOM-killed at 19 GB: refused by memory
    assert n <= 1 << 30, "this machine has more memory than 2**30 seeds need: the count's own bound refuses first"
    base = {"eval": EVAL[:5], "sweep": ["sweep", "--backend", "cpu", "--steps", "2"],
            "demos": ["demos", "--backend", "cpu"], "compare": ["compare", "--backend", "mjx-warp"]}[command]
    t = time.perf_counter()
    assert main([*base, "--seeds", f"0:{n}", "--out", str(tmp_path / "o")]) == 1
    assert time.perf_counter() - t < 1.0
    one_line(capsys, "--seeds", "GiB of memory", "available")
    assert not (tmp_path / "o").exists()


def test_a_cpu_vector_env_past_this_machines_memory_is_refused():
    n = min(_over_memory(BYTES_PER_CPU_ENV), 2**24)
    with pytest.raises(ConfigError, match="num_envs=.*GiB of memory"):
        gym.make_vec("mjx_pusht/PushT-v0", num_envs=n, backend="cpu")


def test_a_mujoco_gl_that_names_no_gl_breaks_only_pixels():
    # MUJOCO_GL=bogus was mujoco's RuntimeError at import: even `tree` died; set aside as a missing library is
    from helpers import ENV, cli, pixels_refusal

    env = {**ENV, "MUJOCO_GL": "bogus"}
    r = cli("tree", env=env)
    assert r.returncode == 0 and "kinematic tree" in r.stdout, r.stderr[-500:]
    p = pixels_refusal(env)
    assert "REFUSED MUJOCO_GL='bogus' is not a GL MuJoCo knows: set MUJOCO_GL to egl, osmesa or glfw" in p.stdout, \
        p.stderr[-500:]


@pytest.mark.parametrize("below", ["", "/sub"])
def test_a_file_as_the_jax_cache_is_one_line_before_any_file(below, tmp_path, monkeypatch, capsys):
    # was FileExistsError's traceback from the cache's set-up, after .run.json was written into --out
    (tmp_path / "f").write_text("x")
    monkeypatch.setenv("MJX_PUSHT_JAX_CACHE", str(tmp_path / "f") + below)
    assert main([*EVAL[:1], "--backend", "mjx-jax", *EVAL[3:], "--out", str(tmp_path / "o")]) == 1
    one_line(capsys, "MJX_PUSHT_JAX_CACHE=", "is a file, not a folder")
    assert not (tmp_path / "o").exists()


def test_a_state_from_the_other_backends_env_is_the_packages_one_line():
    # a cpu State to an MJX env was JAX's TypeError (_Lockstep), an MJX one to a cpu env AttributeError ('copy');
    # no step compiles here: both are refused at the door
    from mujoco import mjx

    from mjx_pusht.envs.functional import PushTEnv

    cpu, jx = PushTEnv(), PushTEnv(backend="mjx-jax")
    state = cpu.reset(np.arange(2))
    with pytest.raises(ConfigError, match="runs on mjx-jax, but the State came from a cpu env"):
        jx.step(state, np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="runs on cpu, but the State came from an MJX env"):
        cpu.step(state._replace(data=mjx.make_data(jx.model)), np.zeros((2, 2)))
    assert np.isfinite(cpu.step(state, np.zeros((2, 2))).obs["state"]).all()  # its own State still steps


CONTROLLERS = """
import os
import numpy as np
def osexit(obs, t): os._exit(0)
def cplx(obs, t): return np.zeros(obs["state"].shape[:-1] + (2,), complex)
def boolean(obs, t): return np.ones(obs["state"].shape[:-1] + (2,), bool)
def as_list(obs, t): return [[0.0, 0.0]] * len(obs["state"])
def scalar(obs, t): return 3
"""


@pytest.fixture
def controllers(tmp_path, monkeypatch):
    (tmp_path / "ctl5.py").write_text(CONTROLLERS)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


@pytest.mark.parametrize("name, words", [
    ("osexit", "called os._exit(0)"),  # ended the run silently with exit 0 and no table
    ("cplx", "dtype complex128; actions are real numbers"),  # the imaginary part dropped with a warning
    ("boolean", "dtype bool; actions are real numbers"),  # True became a velocity of 1 m/s
    ("scalar", "returned an action of a int; expected shape (2, 2)"),  # said "shape None"
])
def test_a_controllers_bad_actions_are_one_line(name, words, controllers, capsys):
    assert main([*EVAL, "--controller", f"ctl5:{name}", "--out", str(controllers / "o")]) == 1
    one_line(capsys, f"controller ctl5:{name}", words)
    assert os._exit.__module__ == "posix"  # the real one is back


def test_a_controller_returning_a_list_of_the_right_shape_runs_as_its_array(controllers, capsys):
    # was refused as "an action of shape None"; zero actions as a list are the zero controller's episodes
    from mjx_pusht.io.outputs import read_table

    assert main([*EVAL, "--controller", "ctl5:as_list", "--out", str(controllers / "l")]) == 0
    assert main([*EVAL, "--controller", "zero", "--out", str(controllers / "z")]) == 0
    got, want = (read_table(controllers / k / "per_episode.parquet") for k in "lz")
    for column in ("final_coverage", "pusher_final_x", "pusher_final_y", "tee_final_yaw"):
        np.testing.assert_array_equal(got[column], want[column])


@pytest.mark.parametrize("argv, words", [
    ([*EVAL, "--video-size", "64"], "--video-size only shapes --video's picture"),  # ignored without a word
    ([*EVAL, "--video-episodes", "2"], "--video-episodes only shapes --video's picture"),
    (["scene", "--no-rerun", "--smoke", "--steps", "50"], "--smoke is the fixed 120-step run"),  # 50 ignored
    (["compare", "--evals", "a", "b", "--seeds", "5"], "their seeds are theirs, so --seeds is not taken"),
])
def test_a_flag_that_would_be_ignored_is_refused_before_any_file(argv, words, tmp_path, capsys):
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    one_line(capsys, words)
    assert not (tmp_path / "o").exists()


def test_tree_colliders_honours_the_pusher(capsys):
    # the table was the cylinder's whatever --pusher said; MuJoCo C's own pair functions tell the shapes apart
    pytest.importorskip("warp")
    tables = {}
    for pusher in ("cylinder", "capsule"):
        assert main(["tree", "--colliders", "--json", "--pusher", pusher]) == 0
        import json

        tables[pusher] = {tuple(r["geoms"]): r for r in json.loads(capsys.readouterr().out)}
    pair = ("tee_bar", "pusher_tip")
    assert tables["cylinder"][pair]["types"] == ["box", "cylinder"]
    assert tables["capsule"][pair]["types"] == ["box", "capsule"]
    assert tables["capsule"][pair]["mujoco_c"] != tables["cylinder"][pair]["mujoco_c"]
    assert tables["capsule"][pair]["mjx_jax"] == tables["cylinder"][pair]["mjx_jax"]  # MJX-JAX's capsule either way


@pytest.mark.parametrize("name", ["tee_mass", "tee_damping", "tee_frictionloss"])
def test_param_and_randomize_refuse_the_same_parameters_on_gym_pusht(name, tmp_path, capsys):
    # --param tee_mass=2 on gym-pusht was accepted, --randomize tee_mass=... refused: one rule now, one reason
    reasons = []
    for flag, value in (("--randomize", "0.5:2"), ("--param", "2")):
        assert main([*EVAL, "--task", "gym-pusht", flag, f"{name}={value}", "--out", str(tmp_path / flag)]) == 1
        line = one_line(capsys, f"{name} means nothing on the gym-pusht task")
        reasons.append(line.split("gym-pusht task: ")[1])
        assert not (tmp_path / flag).exists()
    assert reasons[0] == reasons[1]


def test_a_policy_runs_only_on_the_scene_it_was_trained_on(tmp_path, capsys):
    # demos took a chapter-task policy (GymPushtPolicy refused the same file), and eval ran a gym-pusht policy on
    # the chapter task without a word: one check for every entry now (Task.check_policy)
    from test_tasks import small_policy

    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy
    from mjx_pusht.train.policy import load_checkpoint, save

    gym_pusht = small_policy(tmp_path / "g.msgpack")
    params, meta = load_checkpoint(gym_pusht)
    chapter = tmp_path / "c.msgpack"
    save(chapter, params, {**meta, "config": {}})
    demos = ["demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-progress"]
    for argv, words in (([*demos, "--controller", f"policy:{chapter}"], "trained on the chapter task, not gym-pusht's"),
                        ([*EVAL, "--controller", f"policy:{gym_pusht}"], "trained on the gym-pusht task, not chapter's")):
        assert main([*argv, "--out", str(tmp_path / "o")]) == 1
        one_line(capsys, words)
        assert not (tmp_path / "o").exists()
    with pytest.raises(mjx_pusht.errors.MjxPushtError, match="trained on the chapter task, not gym-pusht's"):
        GymPushtPolicy(chapter)
    assert main([*EVAL, "--task", "gym-pusht", "--controller", f"policy:{gym_pusht}", "--out", str(tmp_path / "e")]) == 0


def test_a_vectors_reset_mask_is_booleans_only():
    v = gym.make_vec("mjx_pusht/PushT-v0", num_envs=3, backend="cpu", autoreset_mode="disabled")
    v.reset(seed=0)
    for mask in (np.array([1, 0, 1]), np.array([1.0, 0.0, 1.0])):  # the integer one was taken as a mask
        with pytest.raises(ConfigError, match=r"reset_mask must be \(3,\) booleans"):
            v.reset(options={"reset_mask": mask})
    obs, _ = v.reset(options={"reset_mask": np.array([True, False, True])})
    assert np.isfinite(obs).all()


def test_vector_set_attr_of_an_unknown_name_is_refused_as_call_of_it_is():
    v = gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu")
    for attempt in (lambda: v.set_attr("bogus_attr", 1), lambda: v.call("bogus_attr")):
        with pytest.raises(AttributeError, match="no attribute 'bogus_attr'") as e:
            attempt()
        assert isinstance(e.value, mjx_pusht.errors.MjxPushtError)
    assert not hasattr(v, "bogus_attr")


def test_a_closed_vector_env_is_not_stepped():
    v = gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu")
    v.reset(seed=0)
    v.close()
    for attempt in (lambda: v.step(np.zeros((2, 2))), lambda: v.reset(seed=0)):
        with pytest.raises(ConfigError, match="the vector env is closed"):
            attempt()


@pytest.mark.parametrize("call, words", [
    (lambda e: e.reset(np.zeros(0, int)), "got none"),  # a 0-world State
    (lambda e: e.reset_to(np.zeros((0, 5))), "got no rows"),
    (lambda e: e.reset_to(np.array([[0, 0, 0, 0.2, 0.2]], complex)), "real numbers, got complex128"),  # a warning only
    (lambda e: e.reset_to(np.array([[True] * 5])), "real numbers, got bool"),
])
def test_the_functional_envs_resets_refuse_no_worlds_and_complex_starts(call, words):
    from mjx_pusht.envs.functional import PushTEnv

    with pytest.raises(ConfigError, match=words):
        call(PushTEnv())


def test_autoreset_refuses_a_depth_of_zero_at_construction():
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.envs.wrappers import AutoReset

    for depth in (0, -1, 2.5, True):
        with pytest.raises(ConfigError, match="AutoReset's depth must be an integer from 1"):
            AutoReset(PushTEnv(), mode="same_step", depth=depth)


@pytest.mark.parametrize("env_id", ["mjx_pusht/PushT-gym-pusht-v0", "mjx_pusht/PushT-v0"])
def test_vector_set_attr_success_threshold_is_honoured_on_every_env(env_id):
    # was "cannot be changed"; references: the vector env given the threshold at make, and the drop-in's single env
    # with its attribute set after make (dropin.md): the same seeds, the same actions, the same steps, rewards, ends
    def run(env, n):
        env.reset(seed=3)
        out = []
        for _ in range(3):
            _, reward, terminated, truncated, _ = env.step(np.zeros((n, 2)) if n else np.zeros(2))
            out.append((np.atleast_1d(reward)[0], np.atleast_1d(terminated)[0]))
        return out

    kw = dict(num_envs=2, backend="cpu", autoreset_mode="disabled", reset_kind="easy")  # the T near its goal
    at_make = run(gym.make_vec(env_id, success_threshold=0.05, **kw), 2)
    after = gym.make_vec(env_id, **kw)
    default = run(after, 2)
    after.set_attr("success_threshold", 0.05)
    assert after.get_attr("success_threshold") == (0.05, 0.05)
    assert run(after, 2) == at_make != default
    assert at_make[0][1] and not default[0][1]  # ended at the first step at 0.05, not at 0.95
    if "gym-pusht" in env_id:
        single = gym.make(env_id, disable_env_checker=True, reset_kind="easy").unwrapped
        single.success_threshold = 0.05
        assert run(single, 0)[0] == at_make[0]
    with pytest.raises(ConfigError, match="success_threshold must be a finite number in"):
        after.set_attr("success_threshold", 1.5)


def test_sweep_resume_into_an_empty_folder_is_refused_as_trains_is(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    for out in ("empty", "new"):
        assert main(["sweep", "--backend", "cpu", "--steps", "2", "--seeds", "2", "--no-rerun", "--no-progress",
                     "--resume", "--out", str(tmp_path / out)]) == 1
        one_line(capsys, "--resume:", "nothing to resume (run without --resume to start)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty"] and not any((tmp_path / "empty").iterdir())


def test_demos_rerun_into_their_own_folder_with_the_same_command(tmp_path, capsys):
    # reliability.md: the same command and settings may rerun into their own folder; demos refused it ("holds a
    # LeRobot dataset; pass --replace"). The rerun writes the dataset again and swaps it in whole: the same bytes
    argv = ["demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-progress", "--out", str(tmp_path / "d")]
    assert main(argv) == 0
    first = {p.relative_to(tmp_path): p.read_bytes() for p in (tmp_path / "d").rglob("*.parquet")}
    assert main(argv) == 0
    assert {p.relative_to(tmp_path): p.read_bytes() for p in (tmp_path / "d").rglob("*.parquet")} == first and first
    capsys.readouterr()
    # a dataset this command did not write (no run file: a user's) is still kept, --share-out or not
    (tmp_path / "u" / "meta").mkdir(parents=True)
    (tmp_path / "u" / "meta" / "info.json").write_text("{}")
    assert main([*argv[:-1], str(tmp_path / "u"), "--share-out"]) == 1
    one_line(capsys, "holds meta, which demos writes but no demos run wrote here")
    assert sorted(p.name for p in (tmp_path / "u").rglob("*")) == ["info.json", "meta"]


def test_ctrl_c_while_eval_draws_its_video_is_one_line_saying_what_is_whole(tmp_path, capsys, monkeypatch):
    import mjx_pusht.io.video as video

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(video, "write", interrupted)  # ^C as the grid is written: exit 130 said nothing
    out = tmp_path / "o"
    assert main([*EVAL, "--video", str(tmp_path / "v.gif"), "--out", str(out)]) == 130
    one_line(capsys, "interrupted: the table and summary in", "are whole", "video was not finished")
    assert (out / "per_episode.parquet").is_file() and (out / "summary.json").is_file()
    assert not (tmp_path / "v.gif").exists()


def test_ctrl_c_in_demos_on_a_fresh_out_does_not_speak_of_an_earlier_dataset(tmp_path, capsys, monkeypatch):
    import mjx_pusht.io.demos as demos

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(demos, "rollout_batch", interrupted)
    argv = ["demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "d")]) == 130
    one_line(capsys, "interrupted: no dataset was finished in")


def test_a_gym_pusht_policys_bool_observation_is_refused():
    from mjx_pusht.boundary import check_gym_pusht_obs

    for obs in (np.ones(5, bool), [True] * 5):  # positions of 1 px
        with pytest.raises(ConfigError, match="observation must be real numbers, got bool"):
            check_gym_pusht_obs(obs, "state")


def test_a_sweeps_param_that_means_nothing_leaves_no_run_file(tmp_path, capsys):
    # the refusal came after .run.json and .parts/manifest.json were written
    assert main(["sweep", "--backend", "cpu", "--steps", "5", "--seeds", "2", "--param", "kp=1", "--no-rerun",
                 "--out", str(tmp_path / "o")]) == 1
    one_line(capsys, "kp means nothing on the chapter task")
    assert not (tmp_path / "o").exists()


def test_ctrl_c_before_a_sweeps_first_chunk_does_not_send_the_user_to_resume(tmp_path, capsys, monkeypatch):
    # the line said "rerun with --resume", which (nothing to resume) is now refused: it says to start instead
    import mjx_pusht.backends.factory as factory

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(factory, "make_backend", interrupted)  # ^C while the backend is built (an MJX compile)
    argv = ["sweep", "--backend", "cpu", "--steps", "2", "--seeds", "2", "--no-rerun", "--no-progress",
            "--out", str(tmp_path / "o")]
    assert main(argv) == 130
    one_line(capsys, "no chunk was finished yet", "rerun without --resume to start")
    monkeypatch.undo()
    assert main(argv) == 0


def test_a_parameter_grid_past_this_machines_memory_is_refused_before_any_file(tmp_path, capsys):
    # each seed is a row per combination: --seeds alone fits, times the grid does not
    grid = 16  # --param kv=1..16: 16 combinations
    n = min(_over_memory(BYTES_PER_SEED) // grid + 1, 1 << 30)
    assert n * BYTES_PER_SEED < available_memory()
    kv = ",".join(str(v) for v in range(1, grid + 1))
    assert main(["sweep", "--backend", "cpu", "--steps", "2", "--seeds", str(n), "--param", f"kv={kv}",
                 "--no-rerun", "--out", str(tmp_path / "o")]) == 1
    one_line(capsys, f"{grid} combinations", "GiB of memory")
    assert not (tmp_path / "o").exists()


@pytest.mark.slow  # compiles MJX-JAX's step three times (about 2 min on a 2-core CPU)
def test_vector_set_attr_success_threshold_recompiles_the_mjx_step():
    # MJX's jitted step holds the threshold as a constant: set after make, it is dropped and compiled again
    def run(env):
        env.reset(seed=3)
        return [tuple(np.asarray(x).tolist() for x in env.step(np.zeros((2, 2)))[1:3]) for _ in range(2)]

    kw = dict(num_envs=2, backend="mjx-jax", autoreset_mode="disabled", reset_kind="easy")
    at_make = run(gym.make_vec("mjx_pusht/PushT-v0", success_threshold=0.05, **kw))
    after = gym.make_vec("mjx_pusht/PushT-v0", **kw)
    default = run(after)
    after.set_attr("success_threshold", 0.05)
    assert run(after) == at_make != default and all(at_make[0][1]) and not any(default[0][1])
