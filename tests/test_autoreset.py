"""Autoreset on the device, hand-offs without copies, and Brax's trainer on the adapter.

The autoreset wrapper's episodes are `eval`'s episodes for the same seeds (to the bit on MuJoCo C);
the gymnasium vector env on MJX-Warp, autoresetting inside its jitted step, follows gymnasium's own
SyncVectorEnv step for step; a torch tensor handed out is the JAX array's memory, not a copy.
"""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.envs.wrappers import AutoReset
from mjx_pusht.errors import ConfigError
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.controllers import Expert
from mjx_pusht.task.episode import Episode


def test_autoreset_episodes_are_evals_rows_for_the_same_seeds():
    """Drive 3 rows with the expert through several autoresets; every finished episode equals eval's row
    for the seed it started from (MuJoCo C both, so to the bit)."""
    episode = Episode(max_steps=12)
    env = AutoReset(PushTEnv(backend="cpu", reset_kind="task", episode=episode), mode="same_step", depth=4)
    seeds = np.array([11, 12, 13])
    state = env.reset(seeds)
    current = seeds.copy()  # the seed each row's episode started from
    ctrl = Expert()
    mode = ctrl.init(state.key)
    finished = []  # (seed, return, coverage, success)
    for _ in range(40):
        a, mode = ctrl.act(mode, state.obs, state.step, state.key)
        used = np.asarray(state.info["used"]).copy()
        state = env.step(state, a)
        ended = np.flatnonzero(state.terminated | state.truncated)
        final = state.info["final"]["metrics"]
        for i in ended:
            finished.append((current[i], final["return"][i], final["coverage"][i], final["success"][i]))
            current[i] = env.pool.seeds[used[i] % env.depth, i]
        mode = np.where(state.terminated | state.truncated, ctrl.init(state.key), mode)
    assert len(finished) >= 9  # three episodes a row at least: every row went through autoresets
    fs = np.array([f[0] for f in finished])
    ref = run_cpu(Scenario(reset="task", controller=Expert(), episode=episode), fs)
    np.testing.assert_array_equal([f[1] for f in finished], ref.episode["return"])
    np.testing.assert_array_equal([f[3] for f in finished], ref.episode["success"])
    # each row's later seeds are its own generator's, seeded by its first seed (gymnasium's rule)
    rng = np.random.default_rng(12)
    from mjx_pusht.task.reset import SEED_MAX

    assert env.pool.seeds[0, 1] == rng.integers(SEED_MAX)


def test_a_row_that_ends_more_often_than_its_queue_repeats_visibly_and_refill_tops_it_up():
    env = AutoReset(PushTEnv(backend="cpu", reset_kind="chapter", episode=Episode(max_steps=1)), depth=2)
    state = env.reset([0, 1])
    first = env.pool.seeds.copy()
    for _ in range(3):
        state = env.step(state, np.zeros((2, 2)))
    assert (np.asarray(state.info["used"]) == 3).all()  # three starts taken from a queue of two: counted
    state = env.refill(state)
    assert not np.array_equal(env.pool.seeds, first)  # the consumed slots hold new seeds


def test_unknown_autoreset_mode_is_one_line():
    with pytest.raises(ConfigError, match="unknown autoreset mode"):
        AutoReset(PushTEnv(backend="cpu"), mode="sometimes")


def test_a_torch_tensor_handed_out_is_the_jax_arrays_memory():
    torch = pytest.importorskip("torch")
    import jax.numpy as jnp

    from mjx_pusht.envs.handoff import from_user, hand_off

    x = jnp.arange(12.0).reshape(4, 3)
    t = hand_off({"obs": x}, "torch")["obs"]
    assert isinstance(t, torch.Tensor)
    assert t.data_ptr() == x.unsafe_buffer_pointer()  # a copy would have its own pointer
    np.testing.assert_array_equal(t.numpy(), np.asarray(x))
    back = from_user(t)
    assert back.unsafe_buffer_pointer() == t.data_ptr()  # actions come in the same way
    n = hand_off({"obs": x}, "numpy")["obs"]
    assert isinstance(n, np.ndarray)


@pytest.mark.slow
@pytest.mark.warp
@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_device_autoreset_follows_gymnasiums_sync_vector_env(mode):
    """MJX-Warp (float32, autoreset in the jitted step) against SyncVectorEnv over MuJoCo C single envs:
    the same flags and zero rewards at the same steps, the same observations to float32 physics' precision."""
    import gymnasium as gym

    import mjx_pusht  # noqa: F401

    kw = dict(max_episode_steps=4, reset_kind="chapter")
    batch = gym.make_vec("mjx_pusht/PushT-v0", num_envs=3, backend="mjx-warp", autoreset_mode=mode,
                         array_type="numpy", depth=2, **kw)
    copies = gym.make_vec("mjx_pusht/PushT-v0", num_envs=3, vectorization_mode="sync",
                          vector_kwargs={"autoreset_mode": gym.vector.AutoresetMode(mode)}, **kw)
    o1, _ = batch.reset(seed=5)
    o2, _ = copies.reset(seed=5)
    np.testing.assert_allclose(o1, o2, atol=1e-5)
    rng = np.random.default_rng(0)
    resets = 0
    for _ in range(11):  # through three autoresets per env, and past the queue's depth (refilled)
        a = rng.uniform(-1, 1, (3, 2))
        o1, r1, t1, u1, i1 = batch.step(a)
        o2, r2, t2, u2, i2 = copies.step(a)
        np.testing.assert_array_equal(t1, t2)
        np.testing.assert_array_equal(u1, u2)
        np.testing.assert_array_equal(r1 == 0, r2 == 0)
        np.testing.assert_allclose(o1, o2, atol=2e-3)
        if mode == "SameStep" and u2.any():
            np.testing.assert_allclose(np.stack(i1["final_obs"][u2]) if i1["final_obs"].dtype == object
                                       else i1["final_obs"][u2], np.stack(i2["final_obs"][u2]), atol=2e-3)
        resets += int(u2.sum())
    assert resets >= 6
    # one compiled step for the whole run: the arrays a reset or a refill hands the step are placed on the
    # device as the step's own outputs are (an uncommitted array makes jit compile the step again)
    assert batch.unwrapped._ar._jitted[3]._cache_size() == 1


@pytest.mark.slow
@pytest.mark.warp
def test_brax_ppo_trains_on_the_adapter_unchanged():
    pytest.importorskip("brax")
    from brax.training.agents.ppo import train as ppo

    from mjx_pusht.envs.brax import BraxPushT, wrap_for_training

    env = BraxPushT(backend="mjx-warp", max_worlds=16, table=256, episode=Episode(max_steps=20))
    evals = []
    _, params, _ = ppo.train(environment=env, num_timesteps=320, num_envs=8, episode_length=20, unroll_length=5,
                             batch_size=8, num_minibatches=2, num_updates_per_batch=1, num_evals=2, num_eval_envs=8,
                             seed=0, wrap_env_fn=wrap_for_training,
                             progress_fn=lambda step, m: evals.append((step, m)))
    assert [s for s, _ in evals] == [0, 320]  # two evaluations: before and after the iterations
    for _, m in evals:  # the task's own metrics came back through Brax's evaluator, and nothing was dropped
        assert np.isfinite(float(m["eval/episode_coverage"])) and float(m["eval/episode_dropped"]) == 0
    assert params is not None


@pytest.mark.slow
def test_brax_sees_a_time_out_as_truncation_and_a_success_as_termination():
    """Brax's GAE bootstraps through a truncation and not through a termination, so the adapter's episode ends must
    say which is which. Half the starts have the T on its target (the task's success, a termination), half never
    reach it in 5 control steps of standing still (a time-out). Each env's ends, read from Brax's `done` and
    `info["truncation"]` across autoresets, are compared with the functional env's own `terminated` / `truncated`
    for the same start on MuJoCo C. Before the fix every time-out read as a termination (truncation 0)."""
    pytest.importorskip("brax")
    import jax
    import jax.numpy as jnp

    from mjx_pusht.envs.brax import BraxPushT, wrap_for_training
    from mjx_pusht.task.reset import start_poses

    steps, n = 5, 8
    starts = start_poses(np.arange(n), reset="task")
    starts[: n // 2, :3] = 0.0  # the T on its target pose: covered, so the episode ends in success
    cpu = PushTEnv(backend="cpu", reset_kind="task", episode=Episode(max_steps=steps))
    ref = cpu.reset_to(starts)
    end = {}  # start row -> (control steps to its end, terminated?) by the functional env itself
    for t in range(1, steps + 1):
        ref = cpu.step(ref, np.zeros((n, 2)))
        for i in np.flatnonzero((ref.terminated | ref.truncated)):
            end.setdefault(int(i), (t, bool(ref.terminated[i])))
    assert sorted(end) == list(range(n)) and {e[1] for e in end.values()} == {True, False}

    env = wrap_for_training(BraxPushT(backend="mjx-jax", max_worlds=n, table=n, starts=starts,
                                      episode=Episode(max_steps=steps)), episode_length=steps)
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(0), n))
    step = jax.jit(env.step)
    age, ends = np.zeros(n, int), 0
    for _ in range(3 * steps):
        row = np.asarray(state.info["seed"]).copy()
        state = step(state, jnp.zeros((n, 2)))
        age += 1
        done, trunc = np.asarray(state.done) > 0, np.asarray(state.info["truncation"])
        for e in range(n):
            if done[e]:
                t, terminated = end[int(row[e])]
                assert (age[e], trunc[e]) == (t, 0.0 if terminated else 1.0), (e, row[e])
                ends += 1
            else:
                assert trunc[e] == 0.0
        age[done] = 0
    assert ends >= n  # every env ended at least once, of both kinds
