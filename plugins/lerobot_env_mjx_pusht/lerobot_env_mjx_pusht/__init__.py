"""LeRobot env plugin: `--env.type=mjx_pusht`, gym-pusht's PushT on mjx_pusht's MuJoCo physics.

    pip install -e plugins/lerobot_env_mjx_pusht     # beside lerobot==0.6.1 and mjx-pusht[gym,warp]
    lerobot-eval --policy.path=... --env.type=mjx_pusht --eval.batch_size=500 --eval.n_episodes=500

LeRobot's `register_third_party_plugins()` (run first by lerobot-eval and lerobot-train) imports
every installed distribution whose name starts with `lerobot_env_`; importing this one registers
`MjxPushtEnv` as the env type `mjx_pusht`. Its fields are those of LeRobot's `PushtEnv` (task,
fps, episode_length, obs_type, render_mode, visualization and observation sizes, features,
features_map), and the env is the drop-in `mjx_pusht/PushT-gym-pusht-v0`: gym-pusht's spaces,
units (pixels, actions an absolute target) and infos, so LeRobot's processors, its
`preprocess_observation` and a policy trained on `lerobot/pusht` see what they see on `pusht`.

`create_envs` builds, where a GPU is present (or `--env.backend` names an MJX backend), ONE vector
env for the whole `--eval.batch_size`: the drop-in's batch (every env one row of one compiled
step, autoreset on the device in LeRobot's SameStep mode, NumPy out as LeRobot's
`preprocess_observation` needs). Elsewhere it builds LeRobot's usual vector env, a
`SyncVectorEnv` (or `AsyncVectorEnv`) of single drop-in envs on MuJoCo C, as `EnvConfig`
builds one for `pusht`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGE, OBS_STATE

import mjx_pusht  # noqa: F401 - registers mjx_pusht/PushT-gym-pusht-v0 with gymnasium
from mjx_pusht.model.randomize import check as check_randomize
from mjx_pusht.model.randomize import parse as parse_randomize
from mjx_pusht.model.scene import SceneSpec

ENV_TYPE = "mjx_pusht"
GYM_ID = "mjx_pusht/PushT-gym-pusht-v0"
TASK = "PushT-gym-pusht-v0"
# the language instruction of LeRobot's `lerobot/pusht` dataset, handed to policies that read one
TASK_DESCRIPTION = "Push the T-shaped block onto the T-shaped target."
BACKENDS = ("auto", "cpu", "mjx-warp", "mjx-jax")
RENDERED = 10  # lerobot-eval's videos: at most this many episodes of a batch are ever rendered


def _name_task(env) -> None:
    """LeRobot reads `task_description` (else `task`) through `env.call` for language-conditioned policies."""
    env.task, env.task_description = TASK, TASK_DESCRIPTION


class BatchRenders(gym.vector.VectorWrapper):
    """The drop-in's batch as lerobot-eval drives it: `call("render")` gives one frame per env for the first
    RENDERED envs (lerobot-eval keeps `call("render")[:n]` with n <= 10), taken from the observation images
    the batch already rendered on the device, instead of drawing every env of the batch on the CPU each step
    (which a state obs_type still does, having no images). Everything else is the batch's own."""

    def __init__(self, env):
        super().__init__(env)
        self._frames = None

    def reset(self, **kwargs):
        obs, info = self.env.reset(**kwargs)
        self._keep(obs)
        return obs, info

    def step(self, actions):
        out = self.env.step(actions)
        self._keep(out[0])
        return out

    def _keep(self, obs) -> None:
        pixels = obs["pixels"] if isinstance(obs, dict) and "pixels" in obs else None
        self._frames = None if pixels is None else np.asarray(pixels[:RENDERED])

    def call(self, name: str, *args, **kwargs):
        if name == "render":
            if self._frames is None:  # no images observed (a state obs_type): the env draws every env's picture
                return tuple(self.env.render() or ())[:RENDERED]
            return tuple(self._frames)
        return self.env.call(name, *args, **kwargs)

    def get_attr(self, name: str):
        return self.env.get_attr(name)


@EnvConfig.register_subclass(ENV_TYPE)
@dataclass
class MjxPushtEnv(EnvConfig):
    """LeRobot's `PushtEnv` config, field for field, for the drop-in; `backend` picks where the batch runs."""

    task: str | None = TASK
    fps: int = 10
    episode_length: int = 300
    obs_type: str = "pixels_agent_pos"
    render_mode: str = "rgb_array"
    visualization_width: int = 384
    visualization_height: int = 384
    observation_height: int = 384
    observation_width: int = 384
    # auto: the drop-in's batch where jax sees a GPU, LeRobot's SyncVectorEnv of MuJoCo C envs elsewhere;
    # cpu: always the latter; mjx-warp / mjx-jax: the batch on that backend (Warp's CPU device without a GPU)
    backend: str = "auto"
    # the coverage an episode succeeds (and ends) at, and the reward's scale, in (0, 1]: gym-pusht's is fixed at 0.95
    # (gym-pusht#24); --env.success_threshold=0.9 scores as ManiSkill's PushT does
    success_threshold: float = 0.95
    # fixed (gym-pusht's goal) or random: a goal pose per episode from its seed, after the block's in the state and
    # environment_state observations (gym-pusht#17); pixel observations take the fixed goal only, so far
    goal: str = "fixed"
    # physics drawn per episode from its seed, as `mjx-pusht eval --randomize`: "kp=0.8:1.2,kv=0.8:1.2" (scale factors
    # on gym-pusht's PD gains, model/randomize.py); the drawn values in each step's info["physics"]. None: gym-pusht's
    randomize: str | None = None
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(2,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(2,)),
        }
    )
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION: ACTION,
            "agent_pos": OBS_STATE,
            "environment_state": OBS_ENV_STATE,
            "pixels": OBS_IMAGE,
        }
    )

    def __post_init__(self):
        if self.task != TASK:
            raise ValueError(f"--env.task for mjx_pusht is {TASK!r} (gym-pusht's PushT on MuJoCo), got {self.task!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"--env.backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        from mjx_pusht.task.goals import check
        from mjx_pusht.validate import fraction

        fraction("--env.success_threshold", self.success_threshold)  # a ConfigError (a ValueError): one line
        check(self.goal)
        if self.randomize is not None:  # refused here, in one line (a ValueError), before LeRobot builds anything
            check_randomize(parse_randomize(self.randomize), SceneSpec(variant="gym-pusht"), "--env.randomize")
        if self.obs_type == "pixels_agent_pos":
            self.features["pixels"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3)
            )
        elif self.obs_type == "environment_state_agent_pos":
            # gym-pusht's T's 8 vertices, and a random goal's T's 8 after them
            self.features["environment_state"] = PolicyFeature(type=FeatureType.ENV,
                                                               shape=(32 if self.goal == "random" else 16,))

    @property
    def package_name(self) -> str:
        return "mjx_pusht"

    @property
    def gym_id(self) -> str:
        return GYM_ID

    @property
    def gym_kwargs(self) -> dict:
        # LeRobot's PushtEnv passes no observation size, so gym-pusht renders its default 96 x 96 whatever
        # observation_height says; here the images are the size the config (and so the policy's features) says
        return {
            "obs_type": self.obs_type,
            "render_mode": self.render_mode,
            "visualization_width": self.visualization_width,
            "visualization_height": self.visualization_height,
            "observation_width": self.observation_width,
            "observation_height": self.observation_height,
            "max_episode_steps": self.episode_length,
            "success_threshold": self.success_threshold,
            "goal": self.goal,
        } | ({"randomize": parse_randomize(self.randomize)} if self.randomize is not None else {})

    def batch_backend(self) -> str | None:
        """The backend the drop-in's batch runs on, or None for LeRobot's usual vector env of MuJoCo C envs."""
        if self.backend == "cpu":
            return None
        if self.backend != "auto":
            return self.backend
        from mjx_pusht.backends.base import resolve

        name, _ = resolve("auto")
        return None if name == "cpu" else name

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, gym.vector.VectorEnv]]:
        backend = self.batch_backend()
        if backend is not None:
            vec = gym.make_vec(GYM_ID, num_envs=n_envs, vectorization_mode="vector_entry_point",
                               backend=backend, autoreset_mode="same_step", array_type="numpy", **self.gym_kwargs)
            _name_task(vec.unwrapped)
            return {self.type: {0: BatchRenders(vec)}}
        return {self.type: {0: self._per_env_vector(n_envs, use_async_envs)}}

    def _per_env_vector(self, n_envs: int, use_async_envs: bool) -> gym.vector.VectorEnv:
        """LeRobot's usual vector env (EnvConfig.create_envs): one drop-in env a sub-env, SameStep autoreset."""
        kwargs = dict(self.gym_kwargs)

        def make_one():
            env = gym.make(GYM_ID, disable_env_checker=self.disable_env_checker, **kwargs)
            _name_task(env.unwrapped)
            return env

        if use_async_envs and n_envs > 1:
            return gym.vector.AsyncVectorEnv([make_one] * n_envs, context="forkserver",
                                             autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
        return gym.vector.SyncVectorEnv([make_one] * n_envs, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
