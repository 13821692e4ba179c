"""The Python API's boundary, fuzzed (tests/fuzzing.py: the property, the budget, the odd values).

Entries: `Scenario`, `SceneSpec`, `Schedule` and `make_backend` (and a run of what they accept), the functional env's
constructor, `reset` and `step`, both gym ids (make, reset with seeds and options, step), their vector envs
(`set_attr`, `call`, reset options, step), the drop-in's reset options, a gym-pusht policy's observation
(`boundary.check_gym_pusht_obs`) and the multi-process options (`Processes`). Each `@example` is a case a hostile
pass or this fuzzer found (a traceback, or an input ignored or honoured wrongly), kept so it stays fixed.
"""

from __future__ import annotations

import functools
import os

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import mjx_pusht  # noqa: F401 - registers the gym ids
from fuzzing import FUZZ, ODD, arrays_near, finite, holds
from mjx_pusht import boundary
from mjx_pusht.envs.functional import PushTEnv
from mjx_pusht.errors import MjxPushtError

IDS = ("mjx_pusht/PushT-v0", "mjx_pusht/PushT-gym-pusht-v0")


def _rows(r) -> dict:
    return {k: v for k, v in vars(r).items() if isinstance(v, np.ndarray)}


@FUZZ
@given(field=st.sampled_from(["scene", "schedule", "params", "reset", "controller", "episode", "randomize"]),
       value=ODD, options=st.dictionaries(st.sampled_from(["nthread", "workers", "threads", "bogus", "x64"]), ODD,
                                          max_size=2))
@example(field="controller", value="expert", options={})  # was AttributeError 'open_loop'
@example(field="controller", value=42, options={})
@example(field="params", value=np.zeros((1, 2, 1)), options={})  # found: an array as a parameter's name, TypeError
@example(field="reset", value="chapter", options={"bogus": 1})  # was accepted and ignored
@example(field="reset", value="chapter", options={"threads": 0})
@example(field="reset", value="chapter", options={"nthread": 0})
def test_scenario_and_make_backend(field, value, options):
    from mjx_pusht import Scenario, Schedule, make_backend

    short = Schedule(settle_steps=5, nudge_steps=5)
    scenario = holds(lambda: Scenario(**{"schedule": short, field: value}))
    if scenario is None:
        return
    backend = holds(lambda: make_backend("cpu", scenario, **options), check=lambda b: None)
    if backend is not None and scenario.controller is None and scenario.schedule.nudge_steps <= 1000:
        holds(lambda: _rows(backend.run([0, 1])))


def _exported():
    """Every callable `import mjx_pusht` exports, and the public ones under it a user builds by hand."""
    import inspect

    from mjx_pusht.envs.wrappers import AutoReset
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    names = {n: getattr(mjx_pusht, n) for n in mjx_pusht.__all__
             if callable(getattr(mjx_pusht, n)) and n not in ("Rollouts", "Tree", "TreeMismatch")}  # results, an error
    names.update({"AutoReset": AutoReset, "GymPushtPolicy": GymPushtPolicy, "PushTEnv.for_task": PushTEnv.for_task})
    return {n: (f, [p for p in inspect.signature(f).parameters if p != "self"]) for n, f in names.items()}


EXPORTED = _exported()


KEYWORDS = sorted({p for _, params in EXPORTED.values() for p in params} | {"bogus", "kind"})


@FUZZ
@given(name=st.sampled_from(sorted(EXPORTED)), args=st.lists(ODD, max_size=3),
       kwargs=st.dictionaries(st.sampled_from(KEYWORDS), ODD, max_size=2))
@example(name="start_poses", args=[[0, 1]], kwargs={"kind": "bogus"})  # seventh pass: Python's TypeError
@example(name="PushTEnv.for_task", args=[], kwargs={})  # found here: the task missing, Python's TypeError
@example(name="GymPushtPolicy", args=[], kwargs={"path": np.zeros((3, 3, 4), bool)})  # found: OSError, name too long
@example(name="make_backend", args=[np.zeros(2)], kwargs={"scenario": None})  # found: an array's truth value
def test_every_exported_callable_called_any_way(name, args, kwargs):
    """Any positional arguments and any keywords (its own names and others), odd values: a result, or one line."""
    function, _ = EXPORTED[name]
    holds(lambda: function(*args, **kwargs), check=lambda r: None)


@FUZZ
@given(scene=st.dictionaries(st.sampled_from(["break_it", "pusher", "variant"]),
                             st.one_of(st.sampled_from(["none", "split-tee", "free-tee", "capsule", "cylinder",
                                                        "chapter", "gym-pusht"]), ODD), max_size=2),
       schedule=st.dictionaries(st.sampled_from(["settle_steps", "nudge_steps", "nudge_ctrl"]),
                                st.one_of(st.integers(-2, 60), st.lists(ODD, max_size=3), ODD), max_size=2))
def test_scene_spec_and_schedule_then_a_run(scene, schedule):
    """SceneSpec's and Schedule's fields, then the chapter study they make run on the CPU: finite rows or one line."""
    from mjx_pusht import Scenario, Schedule, SceneSpec, make_backend

    spec = holds(lambda: SceneSpec(**scene), check=lambda s: None)
    plan = holds(lambda: Schedule(**{"settle_steps": 5, "nudge_steps": 5, **schedule}), check=lambda s: None)
    if spec is not None and plan is not None and plan.settle_steps + plan.nudge_steps <= 200:
        holds(lambda: _rows(make_backend("cpu", Scenario(spec, plan)).run([0, 1])))


@FUZZ
@given(field=st.sampled_from(["backend", "reset_kind", "action_type", "episode", "scene", "pixels", "keypoints",
                              "goal", "threads", "keep_states", "graph_mode", "randomize", "raster",
                              "contacts_per_world", "rows_per_world"]), value=ODD)
@example(field="graph_mode", value="bogus")  # accepted on the CPU
@example(field="scene", value="x")  # was AttributeError
@example(field="threads", value=0)
def test_functional_env_constructor(field, value):
    holds(lambda: PushTEnv(**{field: value}), check=lambda env: None)


@pytest.mark.parametrize("kw", [{"contacts_per_world": -1}, {"rows_per_world": 0}, {"contacts_per_world": 2.5}])
def test_mjx_buffer_sizes_that_are_no_size_are_refused_on_every_backend(kw):
    """A fresh hostile pass found both accepted (docs/notebook/hostile5.md); on MJX, -1 was taken as given."""
    with pytest.raises(MjxPushtError, match="must be an integer from 1"):
        PushTEnv(**kw)


@functools.cache
def _functional() -> PushTEnv:
    return PushTEnv()


@functools.cache
def _holders() -> dict:
    """The objects a user holds, built once: the functional env and its state, an AutoReset and its state, a start
    pool, a gym-pusht policy, a backend."""
    from mjx_pusht import Scenario, make_backend
    from mjx_pusht.envs.wrappers import AutoReset, StartPool
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    env = PushTEnv()
    auto = AutoReset(PushTEnv())
    policy = "outputs/reports/train/ppo-state-gym-pusht-h200/seed-0/policy.msgpack"
    return {"PushTEnv": (env, env.reset(np.arange(2))), "AutoReset": (auto, auto.reset(np.arange(2))),
            "StartPool": (StartPool(env, 2, 2), None),
            "GymPushtPolicy": (GymPushtPolicy(os.path.join(os.path.dirname(__file__), "..", policy)), None),
            "Backend": (make_backend("cpu", Scenario()), None)}


def _methods() -> list[str]:
    """Their public methods, by their classes (nothing built to list them)."""
    import inspect

    from mjx_pusht.backends.cpu import CpuBackend
    from mjx_pusht.envs.wrappers import AutoReset, StartPool
    from mjx_pusht.train.gym_pusht_policy import GymPushtPolicy

    classes = {"PushTEnv": PushTEnv, "AutoReset": AutoReset, "StartPool": StartPool, "GymPushtPolicy": GymPushtPolicy,
               "Backend": CpuBackend}
    return sorted(f"{k}.{n}" for k, c in classes.items() for n, m in inspect.getmembers(c)
                  if not n.startswith("_") and inspect.isfunction(m))


@FUZZ
@given(method=st.sampled_from(_methods()), keyword=st.one_of(st.just("bogus"), st.text(min_size=1, max_size=5)),
       value=ODD, with_state=st.booleans())
@example(method="AutoReset.refill", keyword="bogus", value=1, with_state=True)  # tenth pass: Python's TypeError
def test_every_public_method_refuses_a_keyword_it_does_not_take(method, keyword, value, with_state):
    """Any public method of what a user holds, called with a keyword it does not take (its state first, or not):
    the package's own one line, never Python's TypeError (each pass found one more method that had none)."""
    import inspect

    holder, name = method.split(".")
    obj, state = _holders()[holder]
    function = getattr(obj, name)
    if keyword in inspect.signature(function).parameters:
        return
    args = [state] if with_state and state is not None else []
    with pytest.raises(MjxPushtError):
        function(*args, **{keyword: value})


@FUZZ
@given(seeds=st.one_of(ODD, arrays_near((2,))), state_kind=st.sampled_from(["reset", "odd"]), state=ODD,
       action=st.one_of(arrays_near((2, 2)), ODD))
@example(seeds=[0, 1], state_kind="odd", state=None, action=np.zeros((2, 2)))  # step(None, a): AttributeError
@example(seeds=None, state_kind="reset", state=None, action=None)  # found: reset(None) was a TypeError
@example(seeds=np.zeros(0, int), state_kind="reset", state=None, action=np.zeros((0, 2)))  # a 0-world State
def test_functional_env_reset_and_step(seeds, state_kind, state, action):
    env = _functional()
    started = holds(lambda: env.reset(seeds), check=lambda s: finite(s.obs))
    if started is None:
        return
    holds(lambda: env.step(started if state_kind == "reset" else state, action).obs)


@functools.cache
def _single(env_id: str):
    # without gymnasium's passive checker: once its first checked reset was refused, its own next step check fails
    # with a TypeError of its own (gymnasium 1.4), whatever the env
    return gym.make(env_id, disable_env_checker=True)


OPTIONS = st.dictionaries(st.sampled_from(["reset_to_state", "reset_mask", "lerobot_new_rollout", "other"]),
                          st.one_of(ODD, arrays_near((5,)), arrays_near((2, 5)), arrays_near((2,))), max_size=2)


@FUZZ
@given(env_id=st.sampled_from(IDS), seed=st.one_of(st.none(), st.integers(0, 2**63 - 1), ODD),
       options=st.one_of(st.none(), OPTIONS, ODD), action=st.one_of(arrays_near((2,)), ODD))
@example(env_id=IDS[1], seed=0, options={"reset_to_state": [True] * 5}, action=np.zeros(2))  # agent at (1, 1) px
@example(env_id=IDS[1], seed=0, options={"reset_to_state": np.array([100, 100, 300, 300, 0.5]) + 0j},
         action=np.zeros(2))  # complex: its real part, a ComplexWarning only
@example(env_id=IDS[0], seed=0, options={"reset_mask": [True]}, action=np.zeros(2))  # ignored without a word
@example(env_id=IDS[1], seed=0, options={"reset_mask": [True]}, action=np.zeros(2))
@example(env_id=IDS[0], seed=0, options={"other": 1}, action=np.zeros(2))  # an unknown key: ignored without a word
@example(env_id=IDS[1], seed=0, options={"lerobot_new_rollout": True, "other": 1}, action=np.zeros(2))
def test_gym_ids_reset_and_step(env_id, seed, options, action):
    env = _single(env_id)
    if holds(lambda: env.reset(seed=seed, options=options)) is not None:
        holds(lambda: env.step(action))


# Each id's own keywords (an unknown one is a KeywordError, a TypeError as gym-pusht's, naming the known ones; a render_mode that is not a string
# fails in gymnasium's make before the env is built: AttributeError 'endswith', gymnasium 1.4)
# (max_episode_steps is gymnasium's own TimeLimit's, checked by gymnasium with a ValueError of its own)
MAKE = {IDS[0]: ("obs_type", "action_type", "observation_size", "render_size", "reset_kind", "frame_skip", "success_threshold", "goal", "randomize"),
        IDS[1]: ("obs_type", "block_cog", "damping", "observation_width", "observation_height", "visualization_width",
                 "visualization_height", "success_threshold", "reset_kind", "goal", "randomize")}


@FUZZ
@given(env_id=st.sampled_from(IDS), data=st.data())
@example(env_id=IDS[0], data=None)
def test_gym_ids_make(env_id, data):
    if data is None:  # found: observation_size=None with state observations was a TypeError from the space
        kwargs = {"observation_size": None}
    else:
        kwargs = data.draw(st.dictionaries(st.sampled_from(MAKE[env_id]), ODD, max_size=2))
        kwargs["render_mode"] = data.draw(st.one_of(st.none(), st.sampled_from(["rgb_array", "human", "", "x"])))
    env = holds(lambda: gym.make(env_id, **kwargs), check=lambda e: None)
    if env is not None:
        holds(lambda: env.reset(seed=0))
        env.close()


@functools.cache
def _vector(env_id: str):
    return gym.make_vec(env_id, num_envs=2, backend="cpu")


@FUZZ
@given(env_id=st.sampled_from(IDS), name=st.one_of(st.sampled_from(
           ["num_envs", "success_threshold", "render_size", "obs_type", "mine", "_max_episode_steps", "render",
            "nonexistent"]), ODD),
       value=st.one_of(ODD, st.lists(ODD, min_size=2, max_size=2)), options=st.one_of(st.none(), OPTIONS),
       action=st.one_of(arrays_near((2, 2)), ODD))
@example(env_id=IDS[0], name="num_envs", value=5, options=None, action=np.zeros((2, 2)))  # step refused after
@example(env_id=IDS[0], name="success_threshold", value=0.9, options=None, action=np.zeros((2, 2)))  # traceback
@example(env_id=IDS[0], name="success_threshold", value=[0.9, 0.9], options=None, action=np.zeros((2, 2)))
@example(env_id=IDS[0], name="nonexistent", value=1, options=None, action=np.zeros((2, 2)))
@example(env_id=IDS[0], name="bogus_attr", value=1, options={"reset_mask": np.array([1, 0])},  # both accepted
         action=np.zeros((2, 2)))
def test_vector_envs(env_id, name, value, options, action):
    envs = _vector(env_id)
    holds(lambda: envs.set_attr(name, value), check=lambda r: None)
    holds(lambda: envs.call(name), check=lambda r: None)
    assert envs.num_envs == 2 and envs.unwrapped.num_envs == 2
    if holds(lambda: envs.reset(seed=0, options=options)) is not None:
        holds(lambda: envs.step(action))


def test_make_vec_of_a_huge_batch_is_one_line():
    with pytest.raises(MjxPushtError, match="num_envs must be an integer from 1 to"):
        gym.make_vec(IDS[0], num_envs=2**40, backend="cpu")  # was numpy's MemoryError


VALID_STATE = np.array([256.0, 256.0, 300.0, 300.0, 0.5])


@FUZZ
@given(obs_type=st.sampled_from(["state", "pixels_agent_pos", "pixels", None]),
       obs=st.one_of(ODD, arrays_near((5,)), arrays_near((8,)),
                     st.fixed_dictionaries({"pixels": st.one_of(ODD, arrays_near((4, 4, 3))),
                                            "agent_pos": st.one_of(ODD, arrays_near((2,)))})))
@example(obs_type="state", obs=np.full(5, np.nan))  # the policy answered [nan, nan]
@example(obs_type="state", obs=None)
@example(obs_type="state", obs="abc")
@example(obs_type="state", obs=np.zeros(8))  # a random goal's observation
@example(obs_type="state", obs=np.ones(5, bool))  # bools as positions
@example(obs_type="state", obs={"pixels": np.zeros((96, 96, 3), np.uint8), "agent_pos": np.zeros(2)})
def test_a_gym_pusht_policys_observation(obs_type, obs):
    holds(lambda: boundary.check_gym_pusht_obs(obs, obs_type))


def test_a_valid_gym_pusht_observation_passes():
    boundary.check_gym_pusht_obs(VALID_STATE, "state")
    boundary.check_gym_pusht_obs({"pixels": np.zeros((96, 96, 3), np.uint8), "agent_pos": VALID_STATE[:2]},
                                 "pixels_agent_pos")


HOSTS = st.one_of(st.sampled_from(["127.0.0.1", "localhost", "[::1]", "::1", "node-1.cluster", "host with space",
                                   "", "a..b", "-x", "é.com"]), st.text(max_size=12))
PORTS = st.one_of(st.integers(-5, 70000).map(str), st.sampled_from(["99999", "0", "65535", "", "x", "٣", "1e3"]))


@FUZZ
@given(process_id=ODD, num_processes=st.one_of(st.integers(0, 3), ODD),
       coordinator=st.one_of(st.none(), st.builds(lambda h, p: f"{h}:{p}", HOSTS, PORTS), ODD), peer_timeout=ODD)
@example(process_id=0, num_processes=1, coordinator="127.0.0.1:12345", peer_timeout=300.0)  # ignored, or a hang
@example(process_id=0, num_processes=2, coordinator="127.0.0.1:99999", peer_timeout=300.0)  # OverflowError in bind
@example(process_id=0, num_processes=2, coordinator="host with space:1", peer_timeout=300.0)  # a hang
def test_multi_process_options(process_id, num_processes, coordinator, peer_timeout):
    from mjx_pusht.study.distributed import Processes

    p = holds(lambda: Processes(process_id, num_processes, coordinator, peer_timeout), check=lambda p: None)
    if p is not None:  # what it took is what it will use: a coordinator only with several processes
        assert (p.coordinator is None) == (p.num_processes == 1)
        assert isinstance(p.num_processes, int) and 0 <= p.process_id < p.num_processes
        if p.coordinator:
            port = int(p.coordinator.rsplit(":", 1)[1])
            assert 1 <= port <= 65535


def test_the_property_catches_what_it_should():
    """The property itself: a foreign exception, a two-line error and a NaN each fail it."""
    from mjx_pusht.errors import ConfigError

    class TwoLines(ConfigError):
        def __str__(self):
            return "two\nlines"

    for bad in (lambda: int("x"), lambda: (_ for _ in ()).throw(TwoLines()), lambda: np.nan,
                lambda: {"obs": np.array([1.0, np.inf])}):
        with pytest.raises((AssertionError, ValueError)):
            holds(bad)
    assert holds(lambda: (_ for _ in ()).throw(ConfigError("one line"))) is None
