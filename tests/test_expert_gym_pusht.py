"""The expert for gym-pusht's task solves it: in gym-pusht 0.1.8 itself (pymunk), on the drop-in, and under jit.

Its premise is checked against pymunk too: a push moves gym-pusht's block as a free body given an impulse
along the face normal (frictionless contacts, no velocity kept between steps), the model it plans with.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.expert_gym_pusht import run_dropin, run_gym_pusht
from mjx_pusht.model import gym_pusht as frame
from mjx_pusht.task.controllers import ControllerError, load, seed_key
from mjx_pusht.task.expert_gym_pusht import CONTACTS, ExpertGymPusht, _twists
from mjx_pusht.task.reset import gym_pusht_starts
from mjx_pusht.task.rules import observe

gym_pusht = pytest.importorskip("gym_pusht")
# held-out starts (the expert was tuned on seeds below 2,048), gym-pusht's reset(seed=s) each
SEEDS = np.arange(1_000_000_000, 1_000_000_016)


@pytest.mark.slow  # ~8 s on this 2-core CPU: pymunk and shapely's coverage, one step at a time
def test_the_expert_succeeds_in_gym_pusht_itself():
    """gym-pusht's own env, its own is_success (coverage > 0.95) within 300 control steps: 15 of 16 at least."""
    out = run_gym_pusht(SEEDS)
    assert (out["steps_to_success"] > 0).sum() >= 15, out["steps_to_success"]


def test_the_expert_succeeds_on_the_dropin():
    """The same starts on the drop-in (MuJoCo C), the task's own success rule: 15 of 16 at least."""
    out = run_dropin(SEEDS)
    assert (out["steps_to_success"] > 0).sum() >= 15, out["steps_to_success"]


def test_a_push_moves_gym_pushts_block_as_the_experts_model_says():
    """The agent pushes the bar's top edge 40 px from the T's axis, stemwards, for 10 px: the block turns
    and moves by the free-body impulse model's twist per pixel times 10, in pymunk itself (within 10%: the
    model is the push's first instant; the T turns ~5 degrees on the way, the lever shortening with it)."""
    from gym_pusht.envs.pusht import PushTEnv

    k = int(np.flatnonzero((CONTACTS[:, 0] == 40.0) & (CONTACTS[:, 1] == 0.0))[0])
    kt, kw = _twists(CONTACTS)
    env = PushTEnv(obs_type="state")
    # the T square to the frame (angle 0: the bar along x, the stem down the image), the agent just above the bar
    env.reset(options={"reset_to_state": [296.0, 300.0 - 16.0, 256.0, 300.0, 0.0]})
    x0, a0 = np.array(env.block.position), env.block.angle
    for target_y in np.linspace(300.0 - 15.0, 300.0 - 5.0, 10):  # 1 px a step, then held
        env.step(np.array([296.0, target_y]))
    for _ in range(10):
        env.step(np.array([296.0, 295.0]))
    pushed = env.agent.position[1] - (300.0 - 15.0)  # how far the agent advanced past first touch
    turn = env.block.angle - a0
    cog0 = x0 + np.array([0.0, frame.COG_PX])
    cog1 = np.array(env.block.position) + frame.COG_PX * np.array([-math.sin(env.block.angle), math.cos(env.block.angle)])
    assert pushed == pytest.approx(10.0, abs=0.1)
    assert turn == pytest.approx(kw[k] * pushed, rel=0.1)
    assert (cog1 - cog0)[1] == pytest.approx(kt[k] * pushed, rel=0.1)
    assert abs((cog1 - cog0)[0]) < 0.1 * kt[k] * pushed  # along the push's normal only: frictionless


@pytest.mark.slow  # ~6 s on this 2-core CPU: compiling the vmapped step
def test_the_expert_runs_under_jit_and_vmap_as_in_numpy():
    """The same targets and carries from jax.jit(jax.vmap(act)) in float32 as from NumPy in float64, on
    gym-pusht's starts with every contact as the carried one (to 0.01 px)."""
    import jax
    import jax.numpy as jnp

    ctrl = ExpertGymPusht()
    starts = gym_pusht_starts(np.arange(len(CONTACTS) + 1))
    obs = observe(starts[:, 3:5], starts[:, 0:3])
    key = seed_key(np.arange(len(starts)))
    carry = np.arange(-1, len(CONTACTS), dtype=np.int32)
    want, want_carry = ctrl.act(carry, obs, 0, key)
    act = jax.jit(jax.vmap(lambda c, o, k: ctrl.act(c, o, 0, k)))
    got, got_carry = act(jnp.asarray(carry), {n: jnp.asarray(v, jnp.float32) for n, v in obs.items()}, jnp.asarray(key))
    np.testing.assert_allclose(frame.to_px(np.asarray(got, np.float64)), frame.to_px(want), atol=0.01)
    np.testing.assert_array_equal(np.asarray(got_carry), want_carry)


def test_load_gives_the_expert_and_refuses_other_actions_for_it():
    ctrl = load("expert-gym-pusht")
    assert isinstance(ctrl, ExpertGymPusht) and ctrl.action_type == "target"
    with pytest.raises(ControllerError, match="commands targets"):
        load("expert-gym-pusht", action_type="velocity")
