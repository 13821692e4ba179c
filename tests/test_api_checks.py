"""The Python API refuses what the command line refuses, with the package's one-line error, through the same
checks (validate.py, model.params.check_values): seeds, parameters, step counts."""

from __future__ import annotations

import numpy as np
import pytest

from mjx_pusht import make_backend
from mjx_pusht.cli.parser import build_parser
from mjx_pusht.errors import MjxPushtError
from mjx_pusht.model.params import BOUNDS, parse_param
from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.scenario import Scenario
from mjx_pusht.task.episode import Episode
from mjx_pusht.task.schedule import Schedule


def _one_line(excinfo) -> str:
    text = str(excinfo.value)
    assert "\n" not in text and isinstance(excinfo.value, MjxPushtError)
    return text


@pytest.mark.parametrize("seeds", [[0.5, 1.7], [True, False], np.array([1.0, 2.0]), [-1, 2], [[0, 1], [2, 3]],
                                   ["0", "1"], [[0], [1, 2]]])
def test_a_backend_refuses_seeds_that_are_not_integers_never_truncating_them(seeds):
    # [0.5, 1.7] used to run seeds 0 and 1, [True, False] seeds 1 and 0
    backend = make_backend("cpu", Scenario(SceneSpec(), Schedule(nudge_steps=2)))
    with pytest.raises(MjxPushtError) as e:
        backend.run(seeds)
    assert "seeds" in _one_line(e)


def test_integer_seeds_of_any_integer_kind_run_as_given():
    backend = make_backend("cpu", Scenario(SceneSpec(), Schedule(nudge_steps=2)))
    for seeds in ([3, 1], np.array([3, 1], np.uint8), (np.int32(3), np.int64(1))):
        assert backend.run(seeds).seeds.tolist() == [3, 1]


@pytest.mark.parametrize("params, word", [
    ((("kv", (-1.0,)),), "kv"), ((("tee_frictionloss", (-5.0,)),), "tee_frictionloss"),
    ((("tee_damping", (-0.5,)),), "tee_damping"), ((("tee_mass", (1e300,)),), "tee_mass"),
    ((("tee_mass", (0.0,)),), "tee_mass"), ((("kv", (float("nan"),)),), "kv"), ((("kv", ("20",)),), "kv"),
    ((("kv", (True,)),), "kv"), ((("kv", ()),), "non-empty"), ((("kv", 20.0),), "non-empty"),
    ((("bogus", (1.0,)),), "unknown parameter 'bogus'"), ((("kv", (1.0,)), ("kv", (2.0,))), "once"),
    ((("kv", tuple(range(1, 65))), ("tee_damping", tuple(range(65)))), "combinations"), ("kv", "pairs"),
])
def test_a_scenario_refuses_parameters_the_cli_refuses(params, word):
    with pytest.raises(MjxPushtError) as e:
        Scenario(params=params)
    assert word in _one_line(e)


def test_the_cli_and_the_api_give_one_answer_on_a_parameter():
    for text, params in (("kv=-1", (("kv", (-1.0,)),)), ("tee_mass=1e300", (("tee_mass", (1e300,)),)),
                         ("tee_frictionloss=-5", (("tee_frictionloss", (-5.0,)),))):
        with pytest.raises(MjxPushtError) as cli:
            parse_param(text)
        with pytest.raises(MjxPushtError) as api:
            Scenario(params=params)
        assert str(cli.value).split(": ", 1)[1] == str(api.value).split(": ", 1)[1]
    assert Scenario(params=(("kv", (5, np.float32(80.0))),)).params == (("kv", (5.0, 80.0)),)


def _pushed(name: str, value: float):
    """Mean northward travel of the pusher and of the T over the chapter's nudge, 8 seeds on MuJoCo C."""
    r = make_backend("cpu", Scenario(params=((name, (value,)),))).run(np.arange(8))
    assert r.finite.all() and r.contained.all() and r.rigid.all()
    return float(np.mean(r.pusher_final[:, 1] - r.pusher_start[:, 1])), float(np.mean(r.final[:, 1] - r.settled[:, 1]))


def test_the_mass_bounds_are_where_the_pusher_still_meets_the_t():
    """At the chapter's 0.105 kg the T is pushed; at the lightest allowed mass it is pushed as far; at the heaviest
    it stops the pusher (it travels less than half as far as it does past the bounds, where it goes through)."""
    lo, hi, _ = BOUNDS["tee_mass"]
    push_free, _ = _pushed("tee_damping", 1e4)  # a T held by damping: the pusher's travel with nothing in its way
    push, tee = _pushed("tee_mass", 0.105)
    assert tee > 0.2
    assert _pushed("tee_mass", lo)[1] > 0.2
    assert _pushed("tee_mass", hi)[0] < push_free / 2


def test_step_counts_are_bounded_integers_in_the_api_as_in_the_cli():
    from mjx_pusht.validate import MAX_FRAME_SKIP, MAX_STEPS

    for bad in (0, 2.5, True, MAX_STEPS + 1, 10**9, "10"):
        with pytest.raises(MjxPushtError):
            Schedule(nudge_steps=bad)
        with pytest.raises(MjxPushtError):
            Schedule(settle_steps=bad)
    for bad in ((0.0, float("nan")), (1.0,), "up"):
        with pytest.raises(MjxPushtError):
            Schedule(nudge_ctrl=bad)
    with pytest.raises(MjxPushtError):
        Episode(frame_skip=MAX_FRAME_SKIP + 1)
    from mjx_pusht.task.controllers import load

    long = Scenario(controller=load("expert"), episode=Episode(max_steps=MAX_STEPS + 1))  # an env's episode may be
    with pytest.raises(MjxPushtError) as e:  # long (it steps once a call); a backend's one rollout may not
        make_backend("cpu", long)
    assert "max_steps" in _one_line(e)
    parser = build_parser()
    for flag in ("sweep --steps", "eval --max-steps"):
        command, option = flag.split()
        with pytest.raises(MjxPushtError):
            parser.parse_args([command, option, str(MAX_STEPS + 1)])
        assert getattr(parser.parse_args([command, option, str(MAX_STEPS)]),
                       option.lstrip("-").replace("-", "_")) == MAX_STEPS
