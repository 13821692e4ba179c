"""The hostile pass's API tries (hostile_pass.py runs and judges them): the gymnasium single and vector envs, the
gym-pusht drop-in, the functional env and the Brax adapter, each given what a careless user would give it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from benchmarks.hostile_pass import Try

ID, DROP_IN = "mjx_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0"
NAN, INF = math.nan, math.inf


def _gym():
    import gymnasium as gym

    import mjx_pusht  # noqa: F401 - registers the ids

    return gym


def make(**kw):
    return lambda: _gym().make(ID, **kw)


def single(**kw):
    """A reset PushT-v0."""
    env = _gym().make(ID, **kw)
    env.reset(seed=0)
    return env


def dropin(**kw):
    env = _gym().make(DROP_IN, **kw)
    env.reset(seed=0)
    return env


def step_then(env_fn, action):
    """Step a fresh env once with `action`; the result is (obs, reward, terminated, truncated, info)."""
    return lambda: env_fn().step(action)


def finite_contained(r):
    obs, reward, term, trunc, info = r
    ok = bool(np.all(np.isfinite(np.asarray(obs, float))) and info.get("contained", True) and info.get("finite", True))
    return ok, f"obs finite and T contained: {ok}"


def episode_length(env_fn, limit: int):
    """Steps with zero action until the episode ends (or `limit` + 5)."""
    def run():
        env = env_fn()
        for k in range(1, limit + 6):
            _, _, term, trunc, _ = env.step(np.zeros(2, np.float32))
            if term or trunc:
                return k
        return None

    return run


def within_pusher_bounds(r):
    obs, *_ = r
    ok = bool(np.all(np.asarray(obs)[:2] >= 0) and np.all(np.asarray(obs)[:2] <= 512))
    return ok, f"agent at {np.round(np.asarray(obs)[:2], 1).tolist()} px (space [0, 512])"


def human_shown(env_id):
    """render_mode='human' on a headless SDL driver: the env opens its window, and after a step the window shows
    the step's picture (an rgb_array env's render of the same state). Returns (ok, note)."""
    def run():
        import os

        os.environ["SDL_VIDEODRIVER"] = "dummy"
        try:
            env = _gym().make(env_id, render_mode="human")
            env.reset(seed=0)
            env.step(env.action_space.sample() * 0)
            import pygame

            shown = np.swapaxes(pygame.surfarray.array3d(pygame.display.get_surface()), 0, 1)
            u = env.unwrapped
            u._window, window = None, u._window
            want = u.render()  # the same picture, handed back instead of shown
            u._window = window
            env.close()
            ok = shown.shape == want.shape and bool(np.array_equal(shown, want))
            return ok, f"window {shown.shape} shows the frame: {ok}"
        finally:
            os.environ.pop("SDL_VIDEODRIVER")

    return run


def vec_length(env_fn, limit: int):
    """Vector steps with zero actions until env 0's episode ends (or `limit` + 5)."""
    def run():
        env = env_fn()
        for k in range(1, limit + 6):
            _, _, term, trunc, _ = env.step(np.zeros((env.num_envs, 2)))
            if term[0] or trunc[0]:
                return k
        return None

    return run


def _reset_dropin(state):
    env = _gym().make(DROP_IN)
    env.reset(options={"reset_to_state": state})
    return env


def _restart_row0():
    env = functional()
    return env.reset_where(env.step(env.reset([0, 1]), np.zeros((2, 2))), [True, False], seeds=[7])


def functional(**kw):
    from mjx_pusht.envs.functional import PushTEnv

    return PushTEnv(**kw)


def vec(**kw):
    return _gym().make_vec(ID, **{"num_envs": 2, "backend": "cpu", **kw})


def vec_reset(**kw):
    env = vec(**kw)
    env.reset(seed=0)
    return env


def tries(root: Path) -> list[Try]:
    from mjx_pusht.task.episode import Episode

    a = lambda surface, what, run, expect="refuse", judge=None: Try(surface, what, run, expect, judge)  # noqa: E731
    f_state = lambda: functional().reset([0, 1])  # noqa: E731
    t = [
        # PushT-v0, the single env on MuJoCo C
        a("PushT-v0", "make(obs_type='bogus')", make(obs_type="bogus")),
        a("PushT-v0", "make(action_type='bogus')", make(action_type="bogus")),
        a("PushT-v0", "make(render_mode='human') (no display on this machine)", make(render_mode="human")),
        a("PushT-v0", "make(render_mode='human') with SDL_VIDEODRIVER=dummy: frames shown", human_shown(ID), "honour",
          lambda r: r),
        a("PushT-v0", "make(obs_type='pixels', observation_size=0)", make(obs_type="pixels", observation_size=0)),
        a("PushT-v0", "make(obs_type='pixels', observation_size=100000)", make(obs_type="pixels", observation_size=100000)),
        a("PushT-v0", "make(max_episode_steps=0)", make(max_episode_steps=0)),
        a("PushT-v0", "make(max_episode_steps=-1) (gymnasium's 'no TimeLimit'): runs past 300",
          episode_length(lambda: single(max_episode_steps=-1), 300), "honour", lambda k: (k is None, f"ended after {k} steps")),
        a("PushT-v0", "make(max_episode_steps=1.5)", make(max_episode_steps=1.5)),
        a("PushT-v0", "make(frame_skip=0)", make(frame_skip=0)),
        a("PushT-v0", "make(reset_kind='bogus')", make(reset_kind="bogus")),
        a("PushT-v0", "make(render_size=0, render_mode='rgb_array')", make(render_size=0, render_mode="rgb_array")),
        a("PushT-v0", "make(max_episode_steps=5): episode ends at step 5", episode_length(lambda: single(max_episode_steps=5), 5),
          "honour", lambda k: (k == 5, f"ended after {k} steps")),
        a("PushT-v0", "make(max_episode_steps=320): episode runs past 300", episode_length(lambda: single(max_episode_steps=320), 320),
          "honour", lambda k: (k == 320, f"ended after {k} steps")),
        *[a("PushT-v0", f"reset(seed={s!r})", (lambda s=s: _gym().make(ID).reset(seed=s))) for s in
          (-1, 2**64, "1", 1.5, True, np.float64(3))],
        a("PushT-v0", "reset(seed=np.int64(3)) (gymnasium itself takes Python ints only)",
          lambda: _gym().make(ID).reset(seed=np.int64(3)), "either"),
        a("PushT-v0", "reset(options={'bogus': 1}) (refused, or ignored as LeRobot's rollout needs)",
          lambda: _gym().make(ID).reset(options={"bogus": 1}), "either"),
        *[a("PushT-v0", f"reset(options={{'reset_to_state': {s}}})",
            (lambda s=s: _gym().make(ID).reset(options={"reset_to_state": s}))) for s in
          ([5, 5, 0, 0, -0.25], [NAN, 0, 0, 0.1, 0.1], [0, 0, 0], [0, 0, 0, 0, 0, 0], "abc", [0.0, 0.0, 0.0, 0.0, 0.0],
           [0.01, 0.01, 0.0, 0.011, 0.011])],
        a("PushT-v0", "reset_to_state [0, 0, 1e9, 0.2, 0.2] (a yaw of 1e9 rad: wrapped, or refused)",
          lambda: _gym().make(ID).reset(options={"reset_to_state": [0, 0, 1e9, 0.2, 0.2]}), "either"),
        a("PushT-v0", "reset_to_state [0.1, 0.1, 0.5, -0.2, -0.2] (valid)",
          lambda: _gym().make(ID).reset(options={"reset_to_state": [0.1, 0.1, 0.5, -0.2, -0.2]}), "honour"),
        *[a("PushT-v0", f"step({v!r}) (a list)", step_then(single, v)) for v in
          ([NAN, 0.0], [INF, 0.0], [-INF, -INF], [0, 0, 0], "a", [[0, 0]])],
        a("PushT-v0", "step([nan, 0]) as an array", step_then(single, np.array([NAN, 0.0]))),
        a("PushT-v0", "step([inf, 0]) as an array", step_then(single, np.array([INF, 0.0]))),
        a("PushT-v0", "step(np.zeros(3))", step_then(single, np.zeros(3))),
        a("PushT-v0", "step(None)", step_then(single, None)),
        a("PushT-v0", "step(['a', 'b'])", step_then(single, ["a", "b"])),
        a("PushT-v0", "step([1e9, -1e9]) (clipped as the space says)", step_then(single, np.array([1e9, -1e9])), "honour",
          finite_contained),
        a("PushT-v0", "action_type='position', step([1e9, -1e9])", step_then(lambda: single(action_type="position"),
                                                                          np.array([1e9, -1e9])), "honour", finite_contained),
        a("PushT-v0", "step before reset", lambda: _gym().make(ID, disable_env_checker=True).step(np.zeros(2))),
        a("PushT-v0", "render before reset", lambda: _gym().make(ID, render_mode="rgb_array").render()),
        # the vector env
        *[a("vector", f"make_vec(num_envs={n!r})", (lambda n=n: vec(num_envs=n))) for n in (0, -1, 1.5, True, "2")],
        a("vector", "make_vec(backend='bogus')", lambda: vec(backend="bogus")),
        a("vector", "make_vec(autoreset_mode='bogus')", lambda: vec(autoreset_mode="bogus")),
        a("vector", "make_vec(array_type='bogus')", lambda: vec(array_type="bogus")),
        a("vector", "make_vec(array_type='jax') on cpu", lambda: vec(array_type="jax")),
        a("vector", "make_vec(threads=0)", lambda: vec(threads=0)),
        a("vector", "make_vec(threads=-2)", lambda: vec(threads=-2)),
        a("vector", "make_vec(threads=1.5)", lambda: vec(threads=1.5)),
        a("vector", "make_vec(render_mode='human')", lambda: vec(render_mode="human")),
        a("vector", "make_vec(max_episode_steps=-2)", lambda: vec(max_episode_steps=-2)),
        a("vector", "make_vec(max_episode_steps=-1) (no limit, as PushT-v0): runs past 300",
          vec_length(lambda: vec_reset(max_episode_steps=-1), 300), "honour", lambda k: (k is None, f"ended after {k} steps")),
        a("vector", "make_vec(max_episode_steps=5): ends at step 5", vec_length(lambda: vec_reset(max_episode_steps=5), 5),
          "honour", lambda k: (k == 5, f"ended after {k} steps")),
        a("vector", "render before reset", lambda: vec(render_mode="rgb_array").render()),
        a("vector", "reset(options={'reset_to_state': [0.01, 0.01, 0, 0.011, 0.011]}) (pusher inside the T)",
          lambda: vec().reset(options={"reset_to_state": [0.01, 0.01, 0, 0.011, 0.011]})),
        a("vector", "reset(options={'reset_mask': [[True, False]]})", lambda: vec_reset().reset(options={"reset_mask": [[True, False]]})),
        a("vector", "reset(options={'reset_mask': [True, 'x']})", lambda: vec_reset().reset(options={"reset_mask": [True, "x"]})),
        a("vector", "make_vec(depth=0)", lambda: vec(depth=0)),
        a("vector", "make_vec(variant='bogus')", lambda: vec(variant="bogus")),
        a("vector", "make_vec(max_episode_steps=0)", lambda: vec(max_episode_steps=0)),
        a("vector", "step([[nan, 0], [0, 0]]) (one row)", lambda: vec_reset().step(np.array([[NAN, 0], [0, 0]]))),
        a("vector", "step([[inf, inf], [-inf, 0]])", lambda: vec_reset().step(np.array([[INF, INF], [-INF, 0]]))),
        a("vector", "step(np.zeros((3, 2))) for 2 envs", lambda: vec_reset().step(np.zeros((3, 2)))),
        a("vector", "step(np.zeros(2)) for 2 envs", lambda: vec_reset().step(np.zeros(2))),
        a("vector", "step before reset", lambda: vec().step(np.zeros((2, 2)))),
        a("vector", "reset(seed=[1, 2, 3]) for 2 envs", lambda: vec().reset(seed=[1, 2, 3])),
        a("vector", "reset(seed=[-1, 2])", lambda: vec().reset(seed=[-1, 2])),
        a("vector", "reset(seed=-1)", lambda: vec().reset(seed=-1)),
        a("vector", "reset(options={'reset_mask': [True]}) for 2 envs", lambda: vec().reset(options={"reset_mask": [True]})),
        a("vector", "reset(options={'reset_to_state': [[nan]*5]*2})",
          lambda: vec().reset(options={"reset_to_state": [[NAN] * 5] * 2})),
        a("vector", "reset(options={'reset_to_state': [5, 5, 0, 0, -0.25]})",
          lambda: vec().reset(options={"reset_to_state": [5, 5, 0, 0, -0.25]})),
        a("vector", "step([[1e9, -1e9], [0, 0]]) (clipped)", lambda: vec_reset().step(np.array([[1e9, -1e9], [0, 0]])),
          "honour", lambda r: (bool(np.isfinite(r[0]).all()), "obs finite")),
        # the gym-pusht drop-in
        a("drop-in", "make(obs_type='bogus')", lambda: _gym().make(DROP_IN, obs_type="bogus")),
        a("drop-in", "make(obs_type='pixels', observation_width=0, observation_height=0)",
          lambda: dropin(obs_type="pixels", observation_width=0, observation_height=0)),
        a("drop-in", "make(observation_width=64, observation_height=96)",
          lambda: _gym().make(DROP_IN, observation_width=64, observation_height=96)),
        a("drop-in", "make(obs_type='pixels', observation_width=-5, observation_height=-5)",
          lambda: dropin(obs_type="pixels", observation_width=-5, observation_height=-5)),
        a("drop-in", "make(render_mode='human') (no display on this machine)", lambda: _gym().make(DROP_IN, render_mode="human")),
        a("drop-in", "make(render_mode='human') with SDL_VIDEODRIVER=dummy: frames shown", human_shown(DROP_IN), "honour",
          lambda r: r),
        a("drop-in", "make_vec(render_mode='human')", lambda: _gym().make_vec(DROP_IN, num_envs=2, backend="cpu",
                                                                             render_mode="human")),
        a("drop-in", "make_vec(num_envs=2, threads=0)", lambda: _gym().make_vec(DROP_IN, num_envs=2, backend="cpu", threads=0)),
        a("drop-in", "make_vec step before reset", lambda: _gym().make_vec(DROP_IN, num_envs=2, backend="cpu").step(
            np.zeros((2, 2)))),
        a("drop-in", "reset_to_state [256, 300, 256, 300, 0] (agent on the block: gym-pusht takes it)",
          lambda: step_then(lambda: _reset_dropin([256, 300, 256, 300, 0]), np.array([256.0, 300.0]))(), "honour",
          finite_contained),
        a("drop-in", "make(block_cog=[nan, 0])", lambda: _gym().make(DROP_IN, block_cog=[NAN, 0])),
        a("drop-in", "make(damping=-1)", lambda: _gym().make(DROP_IN, damping=-1)),
        a("drop-in", "make(visualization_width=0, visualization_height=0)",
          lambda: dropin(visualization_width=0, visualization_height=0).render()),
        a("drop-in", "make(max_episode_steps=0)", lambda: _gym().make(DROP_IN, max_episode_steps=0)),
        a("drop-in", "step([1e9, -1e9]) px (space [0, 512])", step_then(dropin, np.array([1e9, -1e9])), "honour",
          within_pusher_bounds),
        a("drop-in", "step([-100, 600]) px", step_then(dropin, np.array([-100.0, 600.0])), "honour", within_pusher_bounds),
        a("drop-in", "step([nan, 200])", step_then(dropin, np.array([NAN, 200.0]))),
        a("drop-in", "step([inf, 200])", step_then(dropin, np.array([INF, 200.0]))),
        a("drop-in", "step(np.zeros(3))", step_then(dropin, np.zeros(3))),
        a("drop-in", "step(None)", step_then(dropin, None)),
        a("drop-in", "step before reset", lambda: _gym().make(DROP_IN, disable_env_checker=True).step(np.zeros(2))),
        *[a("drop-in", f"reset(options={{'reset_to_state': {s}}})",
            (lambda s=s: _gym().make(DROP_IN).reset(options={"reset_to_state": s}))) for s in
          ([NAN, 0, 0, 0, 0], [0, 0, 0], [1e6, 1e6, 1e6, 1e6, 0], [-50, -50, 256, 256, 0])],
        a("drop-in", "reset_to_state [256, 256, 300, 300, 0.5] (valid, px)",
          lambda: _gym().make(DROP_IN).reset(options={"reset_to_state": [256, 256, 300, 300, 0.5]}), "honour"),
        *[a("drop-in", f"reset(seed={s!r})", (lambda s=s: _gym().make(DROP_IN).reset(seed=s))) for s in (-1, "x", 2**64)],
        a("drop-in", "max_episode_steps=5: episode ends at step 5",
          episode_length(lambda: dropin(max_episode_steps=5), 5), "honour", lambda k: (k == 5, f"ended after {k} steps")),
        # the functional env
        a("functional", "PushTEnv(backend='bogus')", lambda: functional(backend="bogus")),
        a("functional", "PushTEnv(reset_kind='bogus')", lambda: functional(reset_kind="bogus")),
        a("functional", "PushTEnv(action_type='bogus')", lambda: functional(action_type="bogus")),
        a("functional", "PushTEnv(pixels=-1)", lambda: functional(pixels=-1)),
        a("functional", "PushTEnv(pixels=5)", lambda: functional(pixels=5)),
        a("functional", "PushTEnv(threads=0)", lambda: functional(threads=0)),
        a("functional", "PushTEnv(threads=-3)", lambda: functional(threads=-3).reset([0, 1, 2, 3, 4, 5, 6, 7])),
        a("functional", "PushTEnv(threads=1.5)", lambda: functional(threads=1.5)),
        a("functional", "PushTEnv(pixels=True)", lambda: functional(pixels=True)),
        a("functional", "PushTEnv(pixels=100000)", lambda: functional(pixels=100000)),
        a("functional", "PushTEnv(episode=Episode(frame_skip=1.5))", lambda: functional(episode=Episode(frame_skip=1.5))),
        a("functional", "PushTEnv(episode=Episode(success=0))", lambda: functional(episode=Episode(success=0))),
        a("functional", "PushTEnv(episode=Episode(success=1.0)) (valid)", lambda: functional(episode=Episode(success=1.0)),
          "honour"),
        a("functional", "PushTEnv(episode=Episode(max_steps=0))", lambda: functional(episode=Episode(max_steps=0))),
        a("functional", "PushTEnv(episode=Episode(success=2.0))", lambda: functional(episode=Episode(success=2.0))),
        a("functional", "PushTEnv(episode=Episode(success=nan))", lambda: functional(episode=Episode(success=NAN))),
        a("functional", "reset([-1])", lambda: functional().reset([-1])),
        a("functional", "reset([2**64])", lambda: functional().reset([2**64])),
        a("functional", "reset([1.5])", lambda: functional().reset([1.5])),
        a("functional", "reset('abc')", lambda: functional().reset("abc")),
        a("functional", "reset([])", lambda: functional().reset([])),
        a("functional", "reset_to([[nan]*5])", lambda: functional().reset_to([[NAN] * 5])),
        a("functional", "reset_to([[5, 5, 0, 0, -0.25]]) (outside the walls)", lambda: functional().reset_to([[5, 5, 0, 0, -0.25]])),
        a("functional", "reset_to([[0, 0, 0, 0]]) (shape (1, 4))", lambda: functional().reset_to([[0, 0, 0, 0]])),
        a("functional", "reset_to([[0, 0, 0, 0, 0]]) (pusher inside the T)", lambda: functional().reset_to([[0, 0, 0, 0, 0]])),
        a("functional", "reset_to(starts, seeds=[-5])", lambda: functional().reset_to([[0.1, 0.1, 0, -0.2, -0.2]], seeds=[-5])),
        a("functional", "step(state, [[nan, 0], [0, 0]])", lambda: functional().step(f_state(), np.array([[NAN, 0], [0, 0]]))),
        a("functional", "step(state, [[inf, 0], [0, 0]])", lambda: functional().step(f_state(), np.array([[INF, 0], [0, 0]]))),
        a("functional", "step(state, zeros((2, 3)))", lambda: functional().step(f_state(), np.zeros((2, 3)))),
        a("functional", "step(state, zeros((3, 2))) for 2 rows", lambda: functional().step(f_state(), np.zeros((3, 2)))),
        a("functional", "step(state, 'a')", lambda: functional().step(f_state(), "a")),
        a("functional", "step(state, [[1e9, -1e9], [0, 0]]) (clipped)",
          lambda: functional().step(f_state(), np.array([[1e9, -1e9], [0, 0]])), "honour",
          lambda s: (bool(np.isfinite(np.asarray(s.obs["state"])).all() and np.asarray(s.metrics["contained"]).all()),
                     "finite and contained")),
        a("functional", "reset_where(state, mask of 3) for 2 rows", lambda: functional().reset_where(f_state(), [True, False, True], seeds=[5, 6])),
        a("functional", "reset_where(state, [True, False], seeds=[-1])", lambda: functional().reset_where(f_state(), [True, False], seeds=[-1])),
        a("functional", "reset_where(state, [True, True], seeds=[1])", lambda: functional().reset_where(f_state(), [True, True], seeds=[1])),
        a("functional", "reset_where(state, [[True, False]], seeds=[1])", lambda: functional().reset_where(f_state(), [[True, False]], seeds=[1])),
        a("functional", "reset_where(state, [True, False]) (no seeds, no starts)", lambda: functional().reset_where(f_state(), [True, False])),
        a("functional", "reset_where(state, [True, False], starts=[[0, 0, 0, 0, 0]]) (pusher inside the T)",
          lambda: functional().reset_where(f_state(), [True, False], starts=[[0, 0, 0, 0, 0]])),
        a("functional", "reset_where(state, [True, False], starts=[[nan]*5])",
          lambda: functional().reset_where(f_state(), [True, False], starts=[[NAN] * 5])),
        a("functional", "reset_where(state, [True, False], seeds=[7]) (valid): row 0 restarts, row 1 runs on",
          _restart_row0,
          "honour", lambda s: (bool(np.asarray(s.step).tolist() == [0, 1]), f"steps {np.asarray(s.step).tolist()}")),
    ]
    t += _brax_tries(a)
    return t


def _brax_tries(a) -> list[Try]:
    def brax(**kw):
        from mjx_pusht.envs.brax import BraxPushT

        return BraxPushT(**{"backend": "mjx-jax", "max_worlds": 2, "table": 8, **kw})

    def step(action, jit=True, check=False):
        """One world's step (jitted, or eager); `check`: then `env.check(state)`, as the documented contract says."""
        def run():
            import jax
            import jax.numpy as jnp

            env = brax()
            s = jax.jit(env.reset)(jax.random.PRNGKey(0))
            s = (jax.jit(env.step) if jit else env.step)(s, jnp.asarray(action, jnp.float32))
            return env.check(s) if check else s
        return run

    def flagged(s):
        ok = bool(np.asarray(s.metrics["bad_action"]) == 1 and np.isfinite(np.asarray(s.obs)).all())
        return ok, f"metrics['bad_action'] {float(np.asarray(s.metrics['bad_action']))}, obs finite: {ok}"

    def inside_starts():
        return brax(starts=np.array([[0.01, 0.01, 0.0, 0.011, 0.011]] * 8))

    return [
        a("brax", "BraxPushT(obs_type='pixels')", lambda: brax(obs_type="pixels")),
        a("brax", "BraxPushT(backend='cpu')", lambda: brax(backend="cpu")),
        a("brax", "BraxPushT(backend='bogus')", lambda: brax(backend="bogus")),
        a("brax", "BraxPushT(max_worlds=0)", lambda: brax(max_worlds=0)),
        a("brax", "BraxPushT(table=0)", lambda: brax(table=0)),
        a("brax", "BraxPushT(table=-4)", lambda: brax(table=-4)),
        a("brax", "BraxPushT(first_seed=-1)", lambda: brax(first_seed=-1)),
        a("brax", "BraxPushT(first_seed=2**63)", lambda: brax(first_seed=2**63)),
        a("brax", "BraxPushT(reset_kind='bogus')", lambda: brax(reset_kind="bogus")),
        a("brax", "BraxPushT(episode=Episode(max_steps=0))",
          lambda: brax(episode=__import__("mjx_pusht.task.episode", fromlist=["Episode"]).Episode(max_steps=0))),
        a("brax", "BraxPushT(max_worlds=1.5)", lambda: brax(max_worlds=1.5)),
        a("brax", "BraxPushT(table=True)", lambda: brax(table=True)),
        a("brax", "BraxPushT(first_seed=1.5)", lambda: brax(first_seed=1.5)),
        a("brax", "BraxPushT(first_seed=2**63-4, table=8) (the table's last seed past 2**63-1)",
          lambda: brax(first_seed=2**63 - 4)),
        a("brax", "BraxPushT(starts=...) with the pusher inside the T", inside_starts),
        a("brax", "BraxPushT(starts=[[nan]*5]*8)", lambda: brax(starts=np.full((8, 5), NAN))),
        a("brax", "BraxPushT(episode=Episode(success=nan))",
          lambda: brax(episode=__import__("mjx_pusht.task.episode", fromlist=["Episode"]).Episode(success=NAN))),
        a("brax", "step(state, [nan, 0]) (eager)", step([NAN, 0.0], jit=False)),
        a("brax", "step(state, [inf, 0]) (eager)", step([INF, 0.0], jit=False)),
        a("brax", "step(state, [nan, 0]) (jitted), then env.check(state)", step([NAN, 0.0], check=True)),
        a("brax", "step(state, [-inf, 0]) (jitted), then env.check(state)", step([-INF, 0.0], check=True)),
        a("brax", "step(state, [nan, 0]) (jitted): zeroed, flagged in metrics['bad_action']", step([NAN, 0.0]), "honour",
          flagged),
        a("brax", "step(state, [0, 0, 0]) (jitted)", step([0.0, 0.0, 0.0])),
        a("brax", "step(state, [[0, 0]]) (jitted)", step([[0.0, 0.0]])),
        a("brax", "step(state, [0, 0]) (jitted), then env.check(state) (valid)", step([0.0, 0.0], check=True), "honour"),
        a("brax", "step(state, [1e9, -1e9]) (jitted, clipped)", step([1e9, -1e9]), "honour",
          lambda s: (bool(np.isfinite(np.asarray(s.obs)).all()), f"obs finite: {bool(np.isfinite(np.asarray(s.obs)).all())}")),
    ]
