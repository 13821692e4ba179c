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


# Round two: threads, image sizes, episode limits, starts with the pusher in the T, call order, render modes.
def vector_kinds():
    return [lambda **kw: batch(V0, **kw), lambda **kw: batch(DROP_IN, **kw)]


@pytest.mark.parametrize("threads", [0, -3, 1.5, True])
def test_a_thread_count_below_one_is_refused_by_every_entry_point_that_takes_one(threads):
    for make in vector_kinds():
        with pytest.raises(ValueError) as e:
            make(threads=threads)
        one_line(e, "threads", repr(threads))
    with pytest.raises(ValueError) as e:
        PushTEnv(backend="cpu", threads=threads)
    one_line(e, "threads", repr(threads))


@pytest.mark.parametrize("pixels", [-1, 5, 4096, True, 96.0])
def test_the_functional_envs_image_size_is_zero_or_one_the_gym_envs_take(pixels):
    with pytest.raises(ValueError) as e:
        PushTEnv(backend="cpu", pixels=pixels)
    one_line(e, "pixels", repr(pixels))
    if not isinstance(pixels, (bool, float)):
        with pytest.raises(ValueError) as e:
            gym.make(V0, obs_type="pixels", observation_size=pixels)
        one_line(e, "observation_size")


@pytest.mark.parametrize("kw, word", [({"success": 2.0}, "success"), ({"success": float("nan")}, "success"),
                                      ({"success": 0}, "success"), ({"success": "0.9"}, "success"),
                                      ({"frame_skip": 1.5}, "frame_skip"), ({"max_steps": 0}, "max_steps")])
def test_an_episode_that_could_never_or_always_end_is_refused(kw, word):
    from mjx_pusht.task.episode import Episode

    with pytest.raises(ValueError) as e:
        Episode(**kw)
    one_line(e, word)


def run_length(env, limit, vector=False):
    """Zero-action steps until the (first) episode ends, or None after limit + 5."""
    env.reset(seed=0)
    for k in range(1, limit + 6):
        _, _, term, trunc, _ = env.step(np.zeros((env.num_envs, 2)) if vector else np.zeros(2))
        if np.ravel(term)[0] or np.ravel(trunc)[0]:
            return k
    return None


def test_max_episode_steps_minus_one_is_no_limit_in_the_single_and_the_vector_env_alike():
    """gymnasium documents -1 as 'no TimeLimit': the single env then runs past the registered 300 steps, and the
    vector env, which holds its own limit, takes -1 the same way; other values below 1 are refused."""
    assert run_length(gym.make(V0, max_episode_steps=-1), 300) is None
    assert run_length(batch(V0, max_episode_steps=-1), 300, vector=True) is None
    assert run_length(batch(V0, max_episode_steps=7), 7, vector=True) == 7
    for bad in (0, -2, 1.5):
        with pytest.raises(ValueError) as e:
            batch(V0, max_episode_steps=bad)
        one_line(e, "max_episode_steps")


INSIDE = [0.01, 0.01, 0.0, 0.011, 0.011]  # the pusher's centre on the T's bar


def test_a_start_with_the_pusher_inside_the_t_is_refused_where_the_chapters_frame_is_used():
    from mjx_pusht.task.reset import PUSHER_RADIUS
    from mjx_pusht.task.rules import distance_to_tee

    assert distance_to_tee(np.array(INSIDE[3:]), np.array(INSIDE[:3])) < PUSHER_RADIUS  # the input is what it says
    for env in (gym.make(V0), batch(V0)):
        with pytest.raises(ValueError) as e:
            env.reset(options={"reset_to_state": INSIDE})
        one_line(e, "reset_to_state", "inside the T")
    fn = PushTEnv(backend="cpu")
    with pytest.raises(ValueError) as e:
        fn.reset_to([INSIDE])
    one_line(e, "reset_to_state", "inside the T")
    with pytest.raises(ValueError) as e:
        fn.reset_where(fn.reset([0, 1]), [False, True], starts=[INSIDE])
    one_line(e, "reset_to_state", "inside the T", "row(s) 0")
    clear = [0.1, 0.1, 0.0, -0.2, -0.2]
    assert np.allclose(fn.reset_to([clear]).obs["state"][0], [-0.2, -0.2, 0.1, 0.1, 0.0])


def test_the_drop_in_takes_an_agent_on_the_block_as_gym_pusht_does_and_its_physics_stay_sound():
    """gym-pusht's own random reset puts the agent on the block at times (pymunk pushes them apart): the drop-in
    takes such a start, and the step after it is finite with the block inside the walls."""
    env = gym.make(DROP_IN)
    env.reset(options={"reset_to_state": [256, 300, 256, 300, 0]})
    obs, _, _, _, info = env.step(np.array([256.0, 300.0]))
    assert np.isfinite(obs).all() and info["finite"] and info["contained"]


def test_a_vector_env_stepped_or_rendered_before_reset_says_reset_in_one_line():
    from mjx_pusht.errors import ResetNeeded

    for env_id in (V0, DROP_IN):
        for call in (lambda e: e.step(np.zeros((2, 2))), lambda e: e.render()):
            with pytest.raises(RuntimeError) as e:
                call(batch(env_id, render_mode="rgb_array"))
            assert isinstance(e.value, ResetNeeded)
            one_line(e, "reset()")


@pytest.mark.parametrize("mask", [[True, False, True], [[True, False]], [True, "x"], [2, 0]])
def test_a_reset_mask_of_the_wrong_length_or_kind_names_it_in_the_vector_and_the_functional_env(mask):
    envs = batch(V0)
    envs.reset(seed=0)
    with pytest.raises(ValueError) as e:
        envs.reset(options={"reset_mask": mask})
    one_line(e, "reset_mask", "(2,)")
    fn = PushTEnv(backend="cpu")
    with pytest.raises(ValueError) as e:
        fn.reset_where(fn.reset([0, 1]), mask, seeds=[5, 6])
    one_line(e, "mask", "(2,)")


@pytest.mark.parametrize("env_id", [V0, DROP_IN])
def test_render_mode_human_without_a_display_is_one_line_and_check_env_still_passes(env_id, monkeypatch):
    from gymnasium.utils.env_checker import check_env

    for var in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
        monkeypatch.delenv(var, raising=False)
    with pytest.raises(ValueError) as e:
        gym.make(env_id, render_mode="human")
    one_line(e, "render_mode='human'", "display")
    with pytest.raises(ValueError) as e:
        batch(env_id, render_mode="human")
    one_line(e, "render_mode", "'human'")
    env = gym.make(env_id, render_mode="rgb_array")
    assert env.unwrapped.metadata["render_modes"] == ["rgb_array"]  # what works on this machine
    check_env(env.unwrapped, skip_render_check=False)


@pytest.mark.parametrize("env_id", [V0, DROP_IN])
def test_render_mode_human_shows_each_step_in_its_window(env_id, monkeypatch):
    """With a display (SDL's dummy driver stands in for one), the window shows after each step the picture an
    rgb_array env of the same seed and actions renders."""
    pygame = pytest.importorskip("pygame")
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    shown, drawn = gym.make(env_id, render_mode="human"), gym.make(env_id, render_mode="rgb_array")
    assert shown.render_mode == "human" and "human" in shown.unwrapped.metadata["render_modes"]
    action = np.array([0.3, -0.2]) if env_id == V0 else np.array([300.0, 200.0])
    for env in (shown, drawn):
        env.reset(seed=3)
        env.step(action)
    window = np.swapaxes(pygame.surfarray.array3d(pygame.display.get_surface()), 0, 1)
    assert shown.render() is None
    np.testing.assert_array_equal(window, drawn.render())
    shown.close()
    assert not pygame.display.get_init()


@pytest.mark.parametrize("kw, word", [({"max_worlds": 0}, "max_worlds"), ({"table": 0}, "table"),
                                      ({"table": -4}, "table"), ({"max_worlds": 1.5}, "max_worlds"),
                                      ({"first_seed": -1}, "first_seed"), ({"first_seed": 2**63}, "first_seed"),
                                      ({"first_seed": 2**63 - 4, "table": 8}, "last seed")])
def test_the_brax_adapter_refuses_bad_sizes_and_seeds_before_building_anything(kw, word):
    pytest.importorskip("brax")
    from mjx_pusht.envs.brax import BraxPushT

    with pytest.raises(ValueError) as e:
        BraxPushT(backend="mjx-jax", **{"max_worlds": 2, "table": 8, **kw})
    one_line(e, word)


@pytest.mark.slow
def test_the_brax_adapter_checks_actions_eagerly_and_flags_them_per_world_under_jit():
    """Eager: a non-finite action is a ConfigError at once. Jitted (a program cannot raise): the action is zeroed
    before the physics, the world's metrics["bad_action"] turns 1.0, and `check` raises naming the world, its seed,
    the control step and the value; a wrong shape is refused while tracing. Starts with the pusher in the T are
    refused as the gymnasium envs refuse them."""
    pytest.importorskip("brax")
    import jax
    import jax.numpy as jnp

    from mjx_pusht.envs.brax import BraxPushT, wrap_for_training

    env = BraxPushT(backend="mjx-jax", max_worlds=4, table=8, first_seed=100)
    with pytest.raises(ValueError) as e:
        BraxPushT(backend="mjx-jax", max_worlds=4, table=2, starts=np.array([INSIDE, [0.1, 0.1, 0, -0.2, -0.2]]))
    one_line(e, "inside the T")
    s = jax.jit(env.reset)(jax.random.PRNGKey(0))
    with pytest.raises(ValueError) as e:
        env.step(s, jnp.array([np.nan, 0.0]))
    one_line(e, "finite")
    with pytest.raises(ValueError) as e:
        jax.jit(env.step)(s, jnp.zeros(3))
    one_line(e, "shape (2,)")
    wrapped = wrap_for_training(env, episode_length=20)
    states = jax.jit(wrapped.reset)(jax.random.split(jax.random.PRNGKey(1), 4))
    step = jax.jit(wrapped.step)
    good = jnp.zeros((4, 2))
    states = step(states, good)
    env.check(states)  # nothing bad yet: returns
    bad = good.at[2].set(jnp.array([0.0, -np.inf]))
    after = step(states, bad)
    assert np.asarray(after.metrics["bad_action"]).tolist() == [0.0, 0.0, 1.0, 0.0]
    clean = step(states, good)  # the zeroed action is the zero action: the physics never saw the inf
    np.testing.assert_array_equal(np.asarray(after.obs), np.asarray(clean.obs))
    with pytest.raises(ValueError) as e:
        env.check(after)
    seed = int(np.asarray(after.info["seed"])[2])
    one_line(e, "world 2", f"seed {seed}", "control step 1", "-inf")
    assert 100 <= seed < 108
