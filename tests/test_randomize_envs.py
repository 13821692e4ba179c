"""Every env built on the functional one takes `randomize=` and reports each episode's drawn physics in
info["physics"]: the values model/randomize draws for that episode's seed (factor x the scene's own value), and
nothing else changes; nothing asked for, no such key."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import mjx_pusht  # noqa: F401 - registers the gymnasium ids
from mjx_pusht.model.randomize import factors

CHAPTER = {"tee_mass": (0.5, 2.0), "kv": (0.8, 1.2)}
OWN = {"tee_mass": 0.105, "kv": 20.0}  # the chapter's own tee mass (kg) and servo kv (the scene's MJCF)


def drawn(ranges: dict, seeds, own: dict) -> dict:
    """model/randomize's draw of each seed, as the parameters' values."""
    pairs = tuple(sorted(ranges.items()))
    f = factors(pairs, np.asarray(seeds))
    return {name: f[:, j] * own[name] for j, (name, _) in enumerate(pairs)}


def _gym_pusht_own(env) -> dict:
    from mjx_pusht.model.params import CURRENT

    return {name: CURRENT[name](env.unwrapped._env.model) for name in ("kp", "kv")}


def test_pusht_v0_reports_each_episodes_draw_and_otherwise_steps_as_the_env_always_did():
    env = gym.make("mjx_pusht/PushT-v0", randomize=CHAPTER)
    want = drawn(CHAPTER, [7], OWN)
    _, info = env.reset(seed=7)
    assert info["physics"] == pytest.approx({k: v[0] for k, v in want.items()}, rel=1e-12)
    *_, info = env.step(np.array([0.3, -0.2]))
    assert info["physics"] == pytest.approx({k: v[0] for k, v in want.items()}, rel=1e-12)
    # factors of 1 are the scene's own physics: the same observations and info, less the one key
    ones, plain = gym.make("mjx_pusht/PushT-v0", randomize={"tee_mass": (1, 1)}), gym.make("mjx_pusht/PushT-v0")
    (o1, i1), (o0, i0) = ones.reset(seed=3), plain.reset(seed=3)
    assert "physics" not in i0 and i1.pop("physics") == {"tee_mass": pytest.approx(0.105, rel=1e-12)}
    for _ in range(20):
        a = np.array([0.5, 0.4])
        (o1, r1, *_, i1), (o0, r0, *_, i0) = ones.step(a), plain.step(a)
        i1.pop("physics")
        np.testing.assert_array_equal(o1, o0)
        assert r1 == r0 and i1.keys() == i0.keys()


def test_the_vector_env_reports_what_its_single_envs_report_across_autoresets():
    """A vector env of 2 is 2 single envs seeded s, s + 1 (SyncVectorEnv's rule): each new episode's physics too."""
    vec = gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu", randomize=CHAPTER, max_episode_steps=2,
                       autoreset_mode="same_step")
    ones = [gym.make("mjx_pusht/PushT-v0", randomize=CHAPTER, max_episode_steps=2) for _ in range(2)]
    _, info = vec.reset(seed=11)
    singles = [e.reset(seed=11 + i)[1] for i, e in enumerate(ones)]
    for k, v in drawn(CHAPTER, [11, 12], OWN).items():
        np.testing.assert_allclose(info["physics"][k], v, rtol=1e-12)
    assert info["_physics"].all()
    for _ in range(2):  # the second step ends every episode; same_step resets them at once
        *_, info = vec.step(np.zeros((2, 2)))
        singles = [e.step(np.zeros(2))[4] for e in ones]
    singles = [e.reset()[1] for e in ones]  # each single env's next episode, from its own generator
    for k in CHAPTER:
        np.testing.assert_array_equal(info["physics"][k], [s["physics"][k] for s in singles])
        np.testing.assert_array_equal(info["final_info"]["physics"][k], drawn(CHAPTER, [11, 12], OWN)[k])
    assert "physics" not in gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="cpu").reset(seed=0)[1]


def test_the_drop_ins_draw_gym_pushts_gains_per_episode():
    rz = {"kp": (0.5, 2.0), "kv": (0.8, 1.2)}
    env = gym.make("mjx_pusht/PushT-gym-pusht-v0", randomize=rz)
    own = _gym_pusht_own(env)
    _, info = env.reset(seed=5)
    want = drawn(rz, [5, 6], own)
    assert info["physics"] == pytest.approx({k: v[0] for k, v in want.items()}, rel=1e-12)
    _, info = env.reset()  # no seed given: the next seed's draw (the starts still come from gym-pusht's generator)
    assert info["physics"] == pytest.approx({k: v[1] for k, v in want.items()}, rel=1e-12)
    vec = gym.make_vec("mjx_pusht/PushT-gym-pusht-v0", num_envs=2, backend="cpu", randomize=rz)
    _, info = vec.reset(seed=5)
    for k, v in want.items():
        np.testing.assert_allclose(info["physics"][k], v, rtol=1e-12)
    assert "physics" not in gym.make("mjx_pusht/PushT-gym-pusht-v0").reset(seed=5)[1]


@pytest.mark.parametrize("make", [lambda: gym.make("mjx_pusht/PushT-v0", randomize={"kp": (0.5, 2.0)}),
                                  lambda: gym.make("mjx_pusht/PushT-gym-pusht-v0", randomize={"tee_mass": (1, 2)}),
                                  lambda: gym.make_vec("mjx_pusht/PushT-v0", 2, backend="cpu",
                                                       randomize={"kv": (2.0, 1.0)})])
def test_a_bad_range_is_one_line_at_make(make):
    from mjx_pusht.model.params import ParamError

    with pytest.raises(ParamError) as e:
        make()
    assert "\n" not in str(e.value)


@pytest.mark.slow
def test_on_mjx_the_brax_adapter_and_the_vector_env_report_each_seeds_draw():
    """The jitted paths (float32 factors on the device): the Brax adapter's info at reset, after a step and after
    its fresh-start autoreset, and the vector env's jitted info view."""
    import jax

    from mjx_pusht.envs.brax import BraxPushT, wrap_for_training
    from mjx_pusht.task.episode import Episode

    env = BraxPushT(backend="mjx-jax", max_worlds=4, table=8, first_seed=100, randomize=CHAPTER,
                    episode=Episode(max_steps=2))
    wrapped = wrap_for_training(env, episode_length=2)
    s = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(0), 4))  # raw keys, as Brax's trainer passes
    step = jax.jit(wrapped.step)
    for _ in range(3):  # an episode of 2 control steps ends and a fresh one starts
        seeds = np.asarray(s.info["seed"])
        for k, v in drawn(CHAPTER, seeds, OWN).items():
            np.testing.assert_allclose(np.asarray(s.info["physics"][k]), v, rtol=1e-6)
        s = step(s, np.zeros((4, 2), np.float32))
    assert "physics" not in BraxPushT(backend="mjx-jax", max_worlds=1, table=2).reset(jax.random.PRNGKey(0)).info
    vec = gym.make_vec("mjx_pusht/PushT-v0", num_envs=2, backend="mjx-jax", randomize=CHAPTER)
    _, info = vec.reset(seed=11)
    for k, v in drawn(CHAPTER, [11, 12], OWN).items():
        np.testing.assert_allclose(np.asarray(info["physics"][k]), v, rtol=1e-6)


def test_random_goals_and_drawn_physics_combine_each_seed_drawing_both_as_each_draws_alone(tmp_path):
    """A seed's goal (task/goals.py) and its physics (model/randomize.py) come from separate hashes of it: asked for
    together, both are drawn, each equal to its own draw: in the functional env (its worlds' MuJoCo C models carry
    the mass), in eval's table, and in the drop-in, whose unseeded reset keys both on the next seed."""
    import pyarrow.parquet as pq

    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.model import gym_pusht as frame
    from mjx_pusht.study.evaluate import evaluate
    from mjx_pusht.task.goals import goal_poses

    seeds = np.arange(3, 7)
    s = PushTEnv.for_task("chapter", goal="random", randomize=CHAPTER).reset(seeds)
    np.testing.assert_array_equal(s.obs["goal"], goal_poses(seeds, "chapter"))
    want = drawn(CHAPTER, seeds, OWN)
    tee = [m.body("tee").mass[0] for m in s.data.models]  # the welded T is one body of the scene's 0.105 kg
    np.testing.assert_allclose(tee, want["tee_mass"], rtol=1e-12)
    rz = {"kp": (0.5, 2.0)}
    evaluate("expert", seeds, tmp_path / "e", backend="cpu", task="gym-pusht", goal="random", randomize=rz,
             max_steps=3, rerun=False, progress=False)
    t = pq.read_table(tmp_path / "e" / "per_episode.parquet").to_pydict()
    env = gym.make("mjx_pusht/PushT-gym-pusht-v0", goal="random", randomize=rz)
    np.testing.assert_allclose(np.c_[t["goal_x"], t["goal_y"], t["goal_yaw"]], goal_poses(seeds, "gym-pusht"),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(t["param_kp"], drawn(rz, seeds, _gym_pusht_own(env))["kp"], rtol=1e-12)
    env.reset(seed=3)
    for seed in (4, 5):  # no seed given: the next one's goal and physics, not seed 0's every time
        _, info = env.reset()
        origin, angle = frame.pose_to_px(goal_poses([seed], "gym-pusht"))
        np.testing.assert_allclose(info["goal_pose"], [*origin[0], angle[0]], rtol=0, atol=1e-9)
        assert info["physics"]["kp"] == pytest.approx(drawn(rz, [seed], _gym_pusht_own(env))["kp"][0], rel=1e-12)
