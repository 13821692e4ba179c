"""One validation layer: the same input gets the same answer from every entry point, in one line naming it.

Entry points: the gymnasium single env, the vector env (make_vec's entry point and gymnasium's own
SyncVectorEnv), the gym-pusht drop-in and the functional env. Unknown reset options are ignored as
gym-pusht ignores them (LeRobot passes one on every rollout); NaN or inf actions are refused naming
their rows; targets are clipped to the action space; starts outside the walls are refused.
"""

from __future__ import annotations

import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import mjx_pusht  # noqa: E402,F401
from mjx_pusht.envs.functional import PushTEnv  # noqa: E402
from mjx_pusht.errors import MjxPushtError  # noqa: E402

V0, DROP_IN = "mjx_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"
LEROBOT = {"lerobot_new_rollout": True}  # what LeRobot's eval passes on every rollout


def sync(env_id, n=2):
    return gym.vector.SyncVectorEnv([lambda: gym.make(env_id)] * n)


def batch(env_id, n=2, **kw):
    return gym.make_vec(env_id, n, vectorization_mode="vector_entry_point", backend="cpu", **kw)


def one_line(excinfo, *words):
    text = str(excinfo.value)
    assert "\n" not in text and isinstance(excinfo.value, MjxPushtError), text
    for w in words:
        assert w in text, (w, text)


@pytest.mark.parametrize("env_id", [V0, DROP_IN])
@pytest.mark.parametrize("make", [gym.make, sync, batch], ids=["single", "SyncVectorEnv", "make_vec"])
def test_an_unknown_reset_option_is_ignored(env_id, make):
    env = make(env_id)
    plain, _ = env.reset(seed=4)
    with_option, _ = env.reset(seed=4, options=LEROBOT)
    np.testing.assert_array_equal(with_option, plain)
    start = [0.1, 0.1, 0.3, -0.2, 0.2] if env_id == V0 else [100.0, 120.0, 300.0, 260.0, 0.5]
    kept, _ = env.reset(seed=4, options={**LEROBOT, "reset_to_state": start})  # reset_to_state keeps its meaning
    only, _ = env.reset(seed=4, options={"reset_to_state": start})
    np.testing.assert_array_equal(kept, only)
    assert not np.array_equal(kept, plain)


@pytest.mark.parametrize("env_id", [V0, DROP_IN])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_non_finite_action_is_a_one_line_error_naming_the_rows(env_id, bad):
    env = gym.make(env_id)
    env.reset(seed=0)
    with pytest.raises(ValueError) as e:
        env.step(np.array([0.1, bad]))
    one_line(e, "finite")
    for envs in (batch(env_id, 3), sync(env_id, 3)):
        envs.reset(seed=0)
        a = np.zeros((3, 2)) if env_id == V0 else np.full((3, 2), 256.0)
        a[1, 0] = bad
        with pytest.raises(ValueError) as e:
            envs.step(a)
        if envs.__class__.__name__ != "SyncVectorEnv":
            one_line(e, "row(s) 1 ", "finite")
    fn = PushTEnv(backend="cpu")
    s = fn.reset([0, 1, 2])
    with pytest.raises(ValueError) as e:
        fn.step(s, np.where(np.arange(6).reshape(3, 2) == 5, bad, 0.0))
    one_line(e, "row(s) 2 ", "finite")


def test_the_drop_in_clips_targets_to_its_space_as_push_t_v0_clips():
    far, edge = gym.make(DROP_IN), gym.make(DROP_IN)
    far.reset(seed=1), edge.reset(seed=1)
    a, *_ = far.step([1e9, -1e9])
    b, *_ = edge.step([512.0, 0.0])
    np.testing.assert_array_equal(a, b)
    assert 0 <= a[0] <= 512 and 0 <= a[1] <= 512
    v0, v0_edge = gym.make(V0), gym.make(V0)
    v0.reset(seed=1), v0_edge.reset(seed=1)
    np.testing.assert_array_equal(v0.step([5.0, -5.0])[0], v0_edge.step([1.0, -1.0])[0])
    envs, edges = batch(DROP_IN), batch(DROP_IN)
    envs.reset(seed=1), edges.reset(seed=1)
    np.testing.assert_array_equal(envs.step(np.full((2, 2), 1e9))[0], edges.step(np.full((2, 2), 512.0))[0])


# Each bad input, refused by every entry point that takes it, naming the argument.
SEEDS = [-1, 1.5, True, "7", 2**63]


@pytest.mark.parametrize("seed", SEEDS)
def test_a_bad_seed_gets_the_same_answer_everywhere(seed):
    for env in (gym.make(V0), gym.make(DROP_IN), batch(V0), batch(DROP_IN)):
        with pytest.raises(ValueError) as e:
            env.reset(seed=seed)
        one_line(e, "seed")
    if not isinstance(seed, (str, bool)):
        with pytest.raises(ValueError) as e:
            PushTEnv(backend="cpu").reset(np.array([seed]))
        one_line(e, "seeds")


def test_a_start_outside_the_walls_is_refused_naming_reset_to_state():
    pixels_given_as_metres = [5, 5, 0, 0, -0.25]  # gym-pusht's pixel units handed to PushT-v0
    for env in (gym.make(V0), batch(V0)):
        with pytest.raises(ValueError) as e:
            env.reset(options={"reset_to_state": pixels_given_as_metres})
        one_line(e, "reset_to_state", "outside the walls", "[5")
    with pytest.raises(ValueError) as e:
        PushTEnv(backend="cpu").reset_to([pixels_given_as_metres])
    one_line(e, "reset_to_state", "outside the walls")
    for env in (gym.make(DROP_IN), batch(DROP_IN)):
        with pytest.raises(ValueError) as e:
            env.reset(options={"reset_to_state": [100, 100, 900, 100, 0]})
        one_line(e, "reset_to_state", "outside the walls", "900")


def test_bad_sizes_render_modes_masks_and_options_are_one_line_at_construction_or_reset():
    for kw, word in (({"observation_width": 0, "observation_height": 0, "obs_type": "pixels"}, "observation_width"),
                     ({"observation_width": 0}, "observation_width"), ({"render_mode": "text"}, "render_mode")):
        for make in (gym.make, batch):
            with pytest.raises(ValueError) as e:
                make(DROP_IN, **kw)
            one_line(e, word)
    for kw, word in (({"obs_type": "pixels", "observation_size": 0}, "observation_size"),
                     ({"render_mode": "text"}, "render_mode"), ({"obs_type": "rgb"}, "obs_type")):
        for make in (gym.make, batch):
            with pytest.raises(ValueError) as e:
                make(V0, **kw)
            one_line(e, word)
    envs = batch(V0)
    envs.reset(seed=0)
    for mask in ([1, 2], [True], "yes"):
        with pytest.raises(ValueError) as e:
            envs.reset(options={"reset_mask": mask})
        one_line(e, "reset_mask")
    with pytest.raises(ValueError) as e:
        gym.make(V0).reset(options=["reset_to_state"])
    one_line(e, "options")
    with pytest.raises(ValueError) as e:
        gym.make_vec(V0, 0, vectorization_mode="vector_entry_point", backend="cpu")
    one_line(e, "num_envs")
