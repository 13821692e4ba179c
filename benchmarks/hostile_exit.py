"""The hostile pass's tries of issue 57 (hostile_pass.py runs and judges them with the API's): the Python API given
what the CLI refuses, an optional extra that is not installed, a script that ends on a step it never read, and
gymnasium's `call` on the batch vector env."""

from __future__ import annotations

import contextlib
import subprocess
import sys
import textwrap

import numpy as np

from benchmarks.hostile_pass import Try

TOUR_PIECE_2 = textwrap.dedent("""
    import numpy as np
    from mjx_pusht.envs.functional import PushTEnv
    env = PushTEnv(backend="mjx-warp", reset_kind="task", action_type="velocity")
    state = env.reset(np.arange(16))
    state = env.step(state, np.zeros((16, 2), np.float32))
""")


@contextlib.contextmanager
def _hidden(name: str):
    """`name` not importable, as for a user without its extra."""
    saved = sys.modules.get(name, False)
    sys.modules[name] = None
    try:
        yield
    finally:
        if saved is False:
            del sys.modules[name]
        else:
            sys.modules[name] = saved


def without(name: str, run):
    def go():
        with _hidden(name):
            return run()
    return go


def _exits(code: str, timeout: float):
    """A fresh interpreter runs `code`: (exit status, seconds) or (None, timeout) if it did not exit."""
    import time

    t0 = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, timeout
    return r.returncode, time.perf_counter() - t0


def tries(root) -> list[Try]:
    from mjx_pusht import make_backend
    from mjx_pusht.model.scene import SceneSpec
    from mjx_pusht.scenario import Scenario
    from mjx_pusht.task.schedule import Schedule

    a = lambda surface, what, run, expect="refuse", judge=None: Try(surface, what, run, expect, judge)  # noqa: E731
    short = Scenario(SceneSpec(), Schedule(nudge_steps=2))

    def train(algo):
        def run():
            if algo == "dagger":
                from mjx_pusht.train.run import train_dagger

                return train_dagger(None, "cpu", root / "dagger")
            from mjx_pusht.train.ppo import train_ppo

            return train_ppo(None, "mjx-jax", root / "ppo")
        return run

    def load_policy():
        from mjx_pusht.task.controllers import load

        return load(f"policy:{root / 'p.msgpack'}")

    def render_call():
        import gymnasium as gym

        import mjx_pusht  # noqa: F401 - registers the ids

        env = gym.make_vec("mjx_pusht/PushT-v0", num_envs=3, backend="cpu", render_mode="rgb_array", render_size=64)
        env.reset(seed=0)
        return env.call("render")

    def one_frame_each(frames):
        shapes = {np.shape(f) for f in frames}
        return len(frames) == 3 and shapes == {(64, 64, 3)}, f"{len(frames)} results of shapes {sorted(shapes)}"

    def exited(r):
        code, seconds = r
        return code == 0, ("never exited" if code is None else f"exit {code} in {seconds:.0f} s")

    return [
        a("backend", "make_backend('cpu', ...).run([0.5, 1.7])", lambda: make_backend("cpu", short).run([0.5, 1.7])),
        a("backend", "make_backend('cpu', ...).run([True, False])", lambda: make_backend("cpu", short).run([True, False])),
        a("backend", "make_backend('cpu', ...).run(['0', '1'])", lambda: make_backend("cpu", short).run(["0", "1"])),
        a("backend", "make_backend('cpu', 'not a scenario')", lambda: make_backend("cpu", "scenario")),
        a("Scenario", "Scenario(params=(('kv', (-1.0,)),))", lambda: Scenario(params=(("kv", (-1.0,)),))),
        a("Scenario", "Scenario(params=(('tee_frictionloss', (-5.0,)),))",
          lambda: Scenario(params=(("tee_frictionloss", (-5.0,)),))),
        a("Scenario", "Scenario(params=(('tee_mass', (1e300,)),))", lambda: Scenario(params=(("tee_mass", (1e300,)),))),
        a("Scenario", "Scenario(params=(('bogus', (1.0,)),))", lambda: Scenario(params=(("bogus", (1.0,)),))),
        a("Scenario", "Scenario(params=(('kv', 20.0),))", lambda: Scenario(params=(("kv", 20.0),))),
        a("Scenario", "Scenario(params=(('kv', (0.0,)),)) (a servo switched off)", lambda: Scenario(params=(("kv", (0.0,)),)),
          "honour"),
        a("Schedule", "Schedule(nudge_steps=10**9)", lambda: Schedule(nudge_steps=10**9)),
        a("Schedule", "Schedule(nudge_steps=2.5)", lambda: Schedule(nudge_steps=2.5)),
        a("Schedule", "Schedule(nudge_ctrl=(nan, 1))", lambda: Schedule(nudge_ctrl=(float("nan"), 1.0))),
        a("extras", "train_dagger(...) without optax [train]", without("optax", train("dagger"))),
        a("extras", "train_ppo(...) without brax [train]", without("brax", train("ppo"))),
        a("extras", "load('policy:PATH') without flax [train]", without("flax", load_policy)),
        a("extras", "an MP4 video without imageio [video]",
          without("imageio", lambda: __import__("mjx_pusht.io.video", fromlist=["check_path"]).check_path(
              root / "v.mp4"))),
        a("extras", "import mjx_pusht.envs.gym_pusht without gymnasium [gym] (a fresh interpreter)",
          lambda: _exits("import sys; sys.modules['gymnasium'] = None\ntry:\n import mjx_pusht.envs.gym_pusht\n"
                         "except ImportError as e:\n assert \"pip install 'mjx-pusht[gym]'\" in str(e), e\n"
                         " raise SystemExit(0)\nraise SystemExit(1)", 120), "honour", exited),
        a("exit", "the README's tour, piece 2: PushTEnv(backend='mjx-warp'), reset, step, never read (16 envs)",
          lambda: _exits(TOUR_PIECE_2, 110), "honour", exited),
        a("vector", "PushT-v0 vector env (3 envs, rgb_array): call('render')", render_call, "honour", one_frame_each),
    ]
