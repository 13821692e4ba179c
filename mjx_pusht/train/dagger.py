"""DAgger: distil the scripted expert into a network that acts from observations alone.

Each iteration the student drives a batch of fresh task episodes (mixed with the expert, with
probability `beta` per control step, which shrinks every iteration from 1: the first iteration
is the expert's own demonstrations), the expert labels every state visited, the labels join
the dataset (kept on the device, a ring of `max_samples`), and the student is refitted to the
whole dataset (flax + optax, warm-started). A held-out set of task seeds, never trained on,
is rolled out by the student alone after every fit: the learning curve.

The rollouts are the environment's own control step (`PushTEnv.advance_one`, the step every
`eval` runs) inside one jitted scan per iteration on MJX, or the CPU env's batch step on MuJoCo C;
the expert is the same `Expert.act` in both, in the env's array namespace.

From pixels (`pixels_agent_pos`: the top camera's 96 x 96 image and the pusher's position) the student
sees the image the env renders in its step (MJX-Warp's ray tracer on the device, MuJoCo C's OpenGL on
the CPU: the same bytes, render/pixels.py), reads the T's pose from it and acts on that reading (policy.py); the
expert still labels from the state, and the fit teaches the reader the pose each image shows. The dataset keeps
no images: a sample holds the 5 numbers of the state that the image is a function of (`RENDER_KEY`
columns, ahead of the features), and each minibatch is rendered again from them inside the fit (on one
H100 a fit step of 512 samples, their render, the CNN's forward and backward pass and Adam's update, took
2.3 ms: notebook change 21), so a ring of millions of samples costs megabytes, not the tens of GB its images
would.

The student has a memory (policy.py): the expert's carry format, which it carries itself. DAgger's
state is then (observation, memory): the expert labels each visited pair by acting *from the
student's memory* (its `act` is a function of (carry, observation)), giving the action to take and
the memory to keep. So the student is taught the expert's response to the situations its own
memory puts it in, not to situations only the expert's memory would have produced.
"""

from __future__ import annotations

import dataclasses
import time
from functools import partial

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.task.controllers import Expert
from mjx_pusht.train.policy import (
    ACTIVATIONS,
    OBS_TYPES,
    feature_size,
    features,
    to_numpy,
)

MEMORY_WEIGHT = 0.01  # the memory heads' cross-entropy against the actions' squared error (m/s)^2
ACTION_REF = 0.1  # m/s: with --action-eps, a label of this size weighs in the loss as without it

# The teacher: by default the expert paced for a student ("paced"): its slowest actions faster, its tolerances coarser.
# The expert's turns end at 4 mm/s against the 3.8 mm/s the T's yaw frictionloss needs, its pushes at 61 mm/s against
# 60, and it slows toward a push's start in proportion to the distance left: a student a few mm/s short there does
# not move the T. And it trims to 0.7 mm and 0.006 rad, where the side it pushes from flips with the error's sign:
# a student that cannot tell the sign at that scale averages the two sides into standing still. Either way the
# student's velocity field has a zero there and the pusher settles in it for good: 49 of 64 failed held-out
# episodes of change 17's policy ended so, and 21 of 47 of a student paced only in speed (notebook change 24). Paced,
# the teacher succeeds as often and sooner (2,048 held-out seeds on MuJoCo C: 99.66% in 86.6 control steps on
# average, the expert 99.46% in 108.6): success (coverage 0.95) comes before those last trims matter.
TEACHERS = {"paced": {"push_min": 0.08, "turn_min": 0.01, "travel_min": 0.06, "pos_tol": 0.002, "yaw_done": 0.015},
            "expert": {}}

# The expert's share at or below which an iteration is "late": `late_fits` fits follow its rollout
LATE_BETA = 0.01

# Held-out evaluation seeds start here; training seeds count up from 0 and must stay below it.
HELD_OUT_FIRST = 1_000_000_000

# A pixel student's sample starts with the observation's state (pusher x, y, tee x, y, yaw): its image's key
RENDER_KEY = 5


@dataclasses.dataclass(frozen=True)
class DaggerConfig:
    obs_type: str = "state"
    envs: int = 4096  # episodes rolled out per iteration
    iterations: int = 10
    hidden: tuple[int, ...] = (256, 256, 256)
    activation: str = "relu"
    learning_rate: float = 1e-3
    batch: int = 4096  # samples per gradient step
    fit_steps: int = 2000  # gradient steps per iteration
    beta_decay: float = 0.7  # the expert's share of control steps: 1, then times this each iteration
    max_samples: int = 8_000_000  # the dataset's ring: the oldest student samples go first
    reset: str = "task"  # the start distribution trained and judged on (reset.RESETS)
    eval_envs: int = 4096  # held-out episodes after each fit
    max_steps: int = 300
    seed: int = 0
    teacher: str = "paced"  # TEACHERS: the expert distilled, as is or paced for a student
    image_batch: int = 512  # a pixel student: of each gradient step's `batch` samples, how many are rendered (`_fit`)
    # A pixel student: the gradient steps an iteration that teach the reader the pose (`_fit`); None: `fit_steps`.
    # (None, not a number, when not given: a run's resume file written before this setting existed still matches.)
    image_steps: int | None = None
    # Fits an iteration once the expert's share is at most LATE_BETA (None: one, as before this setting existed).
    # Late in a run the rollouts add ~5% to a full ring an iteration while the fit's loss still falls: the student
    # under-fits the data it has (notebook, training: "DAgger's seed spread"), so time goes to fitting.
    late_fits: int | None = None
    # The gradient's global norm is clipped to this before Adam in every fit (None: unclipped). Unclipped, the first
    # fit (the untrained network, at the full rate) ended badly for 3 of 16 seeds on one H100: a loss of 0.008-0.014
    # and a student succeeding on 0-0.2% of the held-out seeds, where the other 13 ended at 0.0031-0.0037 and 18-36%;
    # two such runs stayed behind for all their 5 minutes (80.0% and 93.3% held-out, the other three 95.0-96.3%).
    # Clipped at 1.0, the same 16 first fits ended at 0.0028-0.0045 and 4.6-43% (notebook lead4).
    max_grad_norm: float | None = 1.0
    # The first fit is made from this many initialisations (each its own network and minibatches), the one with the
    # lowest loss kept and the rest dropped (None: one, as before this setting existed). Chosen on the training loss,
    # never on held-out seeds. Why: a run's first-fit loss foretold where its 5 minutes ended, on ten 16,384-episode
    # runs (H100): the six at 0.0028-0.0035 ended at 95.0-97.2% held-out, the four above at 80.0-93.3%, the loss
    # level a seed started at holding through the run (notebook lead5).
    first_fits: int | None = None
    # The task trained and judged on (task/tasks.TASKS); None: the chapter's (a resume file from before this
    # setting existed still matches). On gym-pusht's task the teacher is its expert, whose targets are taught as the
    # velocities that reach them (`Task.velocity_of`): a policy acts in velocities on either task.
    task: str | None = None
    # The coverage an episode succeeds (and ends) at, in training and in every judgement; None: the task's own (0.95;
    # and a resume file from before this setting existed still matches).
    success_threshold: float | None = None
    # Goals (task/goals.py): "random", a goal per episode, the student reading it (a goal-conditioned policy: its
    # features gain the goal's, train/policy.features); None: the fixed goal (a resume file from before matches).
    goal: str | None = None
    # The actions' loss weighs each sample's squared error by (0.1^2 + eps^2) / (|label|^2 + eps^2) (eps in m/s; None:
    # plain squared error, as before this setting existed): an error relative to the label's size above eps, a label
    # of 0.1 m/s (what MEMORY_WEIGHT is balanced against) weighed about as before. Why: near the goal
    # gym-pusht's expert nudges the pusher at 0.005-0.02 m/s, the plain loss's RMS error (0.013-0.02 m/s on two H100
    # students) is as large as those nudges, and a student answering 0 there stands still short of success for the
    # rest of the episode: 20 of 27 failures on 256 held-out starts of an H100 student at 91% (notebook lead10).
    action_eps: float | None = None
    # Physics drawn per episode from its seed, in training's rollouts and in every held-out judgement: (name, (lo,
    # hi)) scale factors (model/randomize.py), kept in its checked form; None: the scene's own (a resume file from
    # before this setting existed still matches).
    randomize: tuple | None = None

    def __post_init__(self) -> None:
        if self.randomize is not None:
            from mjx_pusht.model.randomize import check

            object.__setattr__(self, "randomize", check(self.randomize, self.the_task.scene(), "--randomize") or None)
        if self.obs_type not in OBS_TYPES:
            raise ConfigError(f"DAgger trains from {', '.join(OBS_TYPES)} observations, not {self.obs_type!r}")
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"unknown activation {self.activation!r}; choose from {', '.join(ACTIVATIONS)}")
        for name in ("envs", "iterations", "batch", "fit_steps", "max_samples", "eval_envs", "max_steps", "image_batch",
                     "image_steps", "late_fits", "first_fits"):
            if getattr(self, name) is not None and int(getattr(self, name)) < 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(self, name)}")
        if self.envs * self.iterations >= HELD_OUT_FIRST:
            raise ConfigError(f"{self.envs} envs x {self.iterations} iterations would reach the held-out seeds "
                              f"({HELD_OUT_FIRST}+)")
        self.the_task.check_reset(self.reset)
        self.episode()  # a success threshold outside (0, 1] or an unknown goal is a one-line error now
        if self.goal_conditioned and self.obs_type.startswith("pixels"):
            raise ConfigError("--goal random trains from state or keypoints: a pixel student's minibatches are "
                              "rendered from states that carry no goal (not built yet)")
        if self.teacher not in TEACHERS:
            raise ConfigError(f"unknown teacher {self.teacher!r}; choose from {', '.join(TEACHERS)}")
        if self.the_task.name != "chapter" and self.teacher != "expert":
            raise ConfigError(f"the {self.teacher} teacher paces the chapter's expert; on the {self.the_task.name} task "
                              "the teacher is its expert (--teacher expert)")
        if self.image_steps is not None and not self.obs_type.startswith("pixels"):
            raise ConfigError(f"--image-steps teaches a pixel student's image reader; a {self.obs_type} student has none")
        if self.obs_type.startswith("pixels") and self.image_batch > self.batch:
            raise ConfigError(f"--image-batch ({self.image_batch}) must be at most --batch ({self.batch}): it is how "
                              "many of a step's samples are rendered")
        if self.max_grad_norm is not None and not self.max_grad_norm > 0:
            raise ConfigError(f"DAgger: --max-grad-norm must be above 0, got {self.max_grad_norm}")
        if self.action_eps is not None and not 0 < self.action_eps < float("inf"):
            raise ConfigError(f"DAgger: --action-eps must be above 0 (m/s), got {self.action_eps}")
        if not 0.0 <= self.beta_decay <= 1.0:
            raise ConfigError(f"--beta-decay must be in [0, 1], got {self.beta_decay}")

    @property
    def the_task(self):
        from mjx_pusht.task.tasks import get

        return get(self.task or "chapter")

    def episode(self):
        """The episodes trained and judged on: the task's, at `max_steps` and `success_threshold`."""
        return self.the_task.episode(max_steps=self.max_steps, success_threshold=self.success_threshold,
                                     goal=self.goal or "fixed")

    @property
    def goal_conditioned(self) -> bool:
        return self.goal == "random"

    @property
    def memory(self):
        """The format of the teacher's carry, which the student keeps as its memory (task/memory.py)."""
        return self.the_task.memory

    @property
    def image(self) -> int:
        """The side of the image the student sees (0: none)."""
        from mjx_pusht.render.pixels import IMAGE_SIZE

        return IMAGE_SIZE if self.obs_type.startswith("pixels") else 0

    @property
    def reader_steps(self) -> int:
        """A pixel student's image steps an iteration (`_fit`): `image_steps`, or as many as the actions'."""
        return self.fit_steps if self.image_steps is None else self.image_steps

    @property
    def sample_width(self) -> int:
        """A dataset row's width: the features, after the image's key for a pixel student."""
        return feature_size(self.obs_type, self.memory, self.goal_conditioned) + (RENDER_KEY if self.image else 0)

    def beta(self, iteration: int) -> float:
        return self.beta_decay ** iteration

    def fits(self, iteration: int) -> int:
        """How many fits (each `fit_steps`, its learning rate annealed afresh) follow iteration `iteration`'s rollout."""
        return (self.late_fits or 1) if self.beta(iteration) <= LATE_BETA else 1

    def train_seeds(self, iteration: int) -> np.ndarray:
        return np.arange(iteration * self.envs, (iteration + 1) * self.envs, dtype=np.int64)

    def held_out_seeds(self) -> np.ndarray:
        return held_out_seeds(self.eval_envs)


def held_out_seeds(n: int) -> np.ndarray:
    """The first `n` held-out task seeds: never trained on, by either method."""
    return HELD_OUT_FIRST + np.arange(n, dtype=np.int64)


# -- rollouts: the student (mixed with the expert) drives, the expert labels ---------------------------
def _choose(xp, expert, student, take_expert):
    """(action, memory) of the expert where `take_expert`, else the student's."""
    return (xp.where(take_expert[..., None], expert[0], xp.astype(student[0], expert[0].dtype)),
            xp.where(take_expert, expert[1], student[1]))


def _label(xp, action, memory):
    """One row of labels: the expert's action (2) and the memory it keeps (as a float, exact below 2^24)."""
    return xp.concat([xp.astype(action, xp.float32), xp.astype(memory, xp.float32)[..., None]], axis=-1)


def _sample(xp, obs, x, image: int):
    """A dataset row from the features the student read: with its image's key first, for a pixel student."""
    return xp.concat([xp.astype(obs["state"], x.dtype), x], axis=-1) if image else x


class Rollouts:
    """Rolls episodes out on one env with the student, the expert labelling: (features, labels) and outcomes."""

    def __init__(self, env, cfg: DaggerConfig, spread=None):
        """`spread` (devices.Spread; None: JAX's default device): the devices an MJX rollout's seeds are split over."""
        self.env, self.cfg, self.expert, self.spread = env, cfg, teacher(cfg), spread
        self.task = cfg.the_task
        self._compact, self._episodes_jit = {}, None
        self.steps = 0  # the control steps the last rollout ran (its batch's longest episode; on MJX every step)
        self.cut = False  # whether the last rollout stopped at its deadline, episodes unfinished

    def __call__(self, params, norm, seeds, beta, rng: int, learn: int | None = None):
        """Features and expert labels of every live control step of the first `learn` episodes (all if None;
        on the device on MJX), and every episode's outcome. `norm` is (mean, std) of the features; `beta`, the
        expert's share, is one number or one per seed (0 for held-out episodes judged in the same batch)."""
        x, y, n, outcome = self.padded(params, norm, seeds, beta, rng, learn)
        return x[:n], y[:n], outcome

    def padded(self, params, norm, seeds, beta, rng: int, learn: int | None = None, deadline: float | None = None):
        """As calling it, but the samples and labels are the first `n` rows of arrays whose length does not depend
        on how long the episodes ran (on MJX: every live control step's row could be there), returned with `n`:
        (x, y, n, outcomes). DAgger's loop adds them to the ring as they are (`Learner.add(..., n=n)`), so its
        programs keep one shape from iteration to iteration.
        `deadline` (a `time.perf_counter()` reading; MuJoCo C only, whose steps are a host loop): no control step
        starts past it, so the episodes may end cut short: for a rollout learned from, never for one judged."""
        beta = np.broadcast_to(np.asarray(beta, np.float32), (len(seeds),))
        learn = len(seeds) if learn is None else learn
        if self.env.backend == "cpu":
            x, y, outcome = self._cpu(params, norm, seeds, beta, rng, learn, deadline)
            return x, y, len(x), outcome
        self.steps, self.cut = self.cfg.max_steps, False
        return self._mjx(params, norm, seeds, beta, rng, learn)

    def _cpu(self, params, norm, seeds, beta, rng, learn, deadline=None):
        from mjx_pusht.train.policy import apply

        env, cfg = self.env, self.cfg
        meta = student_meta(cfg, norm)
        params = to_numpy(params)
        gen = np.random.default_rng([cfg.seed, rng])
        s = env.reset(seeds)
        memory = self.expert.init(s.key)
        xs, ys = [], []
        self.cut = False
        for self.steps in range(cfg.max_steps + 1):
            done = np.asarray(s.carry["ep"]["done"])
            if done.all() or self.steps == cfg.max_steps:
                break
            if deadline is not None and self.steps and time.perf_counter() > deadline:  # a step's samples at least
                self.cut = True
                break
            live = ~done
            live[learn:] = False  # judged only: their samples are not learned from
            x = features(s.obs, cfg.obs_type, memory, cfg.memory, cfg.goal_conditioned)
            label, label_memory = self.expert.act(memory, s.obs, s.step, s.key)
            student = apply(params, meta, x, s.obs.get("pixels"))
            action, memory = _choose(np, (label, label_memory), student, gen.random(len(seeds)) < beta)
            xs.append(_sample(np, s.obs, x, cfg.image)[live])
            ys.append(_label(np, label, label_memory)[live])
            s = env.step(s, self.task.from_velocity(action, s.obs))
        env.check(s)
        return np.concatenate(xs).astype(np.float32), np.concatenate(ys).astype(np.float32), _outcomes(s)

    def _mjx(self, params, norm, seeds, beta, rng, learn):
        import jax
        import jax.numpy as jnp

        from mjx_pusht.train.devices import Spread

        env, spread = self.env, self.spread or Spread(jax.devices()[:1])
        spread.check(len(seeds), "a rollout's episodes (--envs + --eval-envs)")
        # a program per device on its block of the seeds (devices.py: MJX-Warp's FFI call is not partitioned);
        # each episode's random draws are its seed's, whichever device runs it
        keys = jax.random.split(jax.random.key(self.cfg.seed * 1_000_003 + rng), len(seeds))
        shared, beta = (params, tuple(jnp.asarray(a, jnp.float32) for a in norm)), jnp.asarray(beta)
        self._episodes_jit = self._episodes_jit or jax.jit(self._episodes)  # one, compiled for each device it runs on

        shared = spread.own_copy(shared)
        # every block's inputs on its device before any program runs (start states made on one thread: the env keeps
        # its programs per batch size); then each thread runs its device's and waits for it, as the sweep's do. On 4
        # H200s, copies made while another device's program captured Warp's graph broke it (error 904, lead15)
        blocks = [jax.block_until_ready(jax.device_put((*shared, env.reset(seeds[rows]), beta[rows], keys[rows]),
                                                      dev)) for dev, rows in spread.local(len(seeds))]
        parts = spread.each(lambda *block: jax.block_until_ready(self._episodes_jit(*block)), blocks)
        ends = [_outcomes(env.check(p[0])) for p in parts]
        outcome = {k: spread.gather(np.concatenate([e[k] for e in ends])) for k in ends[0]}
        x, y, live = (spread.join([p[i] for p in parts], axis=1) for i in (1, 2, 3))  # (T, N, ...): N over devices
        if not learn:  # judged only (the last fit's judgement): no samples, and no compaction compiled for them
            return x[0, :0], y[0, :0], 0, outcome
        if learn not in self._compact:
            self._compact[learn] = jax.jit(partial(_compact, learn=learn), out_shardings=spread.sharding(None))
        x, y, count = self._compact[learn](x, y, live)
        return x, y, int(count), outcome

    def _episodes(self, params, norm, s, beta, keys):
        """The batch's episodes: a scan over control steps of the vmapped control step (as the env's own jitted
        step; MJX-Warp's renderer is called per step on the whole batch); stacks (T, N, F), (T, N, 3), (T, N)."""
        import jax
        import jax.numpy as jnp

        from mjx_pusht.train.policy import apply

        cfg = self.cfg
        meta = student_meta(cfg, norm)
        advance = self.env.step_one if cfg.image else self.env.advance_one  # step_one renders the next image

        def one(s, memory, beta, key, t):
            live = ~s.carry["ep"]["done"]
            x = features(s.obs, cfg.obs_type, memory, cfg.memory, cfg.goal_conditioned).astype(jnp.float32)
            label, label_memory = self.expert.act(memory, s.obs, s.step, s.key)
            take = jax.random.uniform(jax.random.fold_in(key, t)) < beta
            action, memory = _choose(jnp, (label, label_memory), apply(params, meta, x, s.obs.get("pixels")), take)
            sample = _sample(jnp, s.obs, x, cfg.image)
            return advance(s, self.task.from_velocity(action, s.obs)), memory, (sample, _label(jnp, label, label_memory), live)

        def body(c, t):
            s, memory, out = jax.vmap(one, in_axes=(0, 0, 0, 0, None))(*c, beta, keys, t)
            return (s, memory), out

        (s, _), (x, y, live) = jax.lax.scan(body, (s, self.expert.init(s.key)), jnp.arange(cfg.max_steps))
        return s, x, y, live


def student_meta(cfg: DaggerConfig, norm) -> dict:
    """What `policy.apply` reads of the student being trained: its normalisation, activation, image size and memory
    format, as its checkpoint will name them (a student decoding its memory in another format than its features
    encode it is taught from memories it never keeps: two H100 runs on gym-pusht's task did, 2026-11-26)."""
    return {"in_mean": norm[0], "in_std": norm[1], "activation": cfg.activation, "image": cfg.image,
            "memory": cfg.memory.meta()}


def teacher(cfg: DaggerConfig):
    """Whom the student learns from, acting in velocities: the chapter's expert (paced, or as is), or another task's
    expert, its targets read as the velocities that reach them. Either way the student keeps its carry as memory."""
    if cfg.the_task.name == "chapter":
        return Expert(**TEACHERS[cfg.teacher])
    from mjx_pusht.task.tasks import as_velocities

    return as_velocities(cfg.the_task.controller("expert"))


def _compact(x, y, live, learn: int):
    """The (T, N, ...) stacks' rows of the first `learn` worlds' live control steps, episode after episode, moved to
    the front of arrays of T * learn rows, and how many they are. The rest of the rows repeat the first (a live step:
    every episode has one), so a check of the whole array checks the samples. A compaction to the count itself gave
    every iteration new shapes: ~20 small programs compiled an iteration (notebook lead7)."""
    import jax.numpy as jnp

    x, y, live = (jnp.swapaxes(a[:, :learn], 0, 1) for a in (x, y, live))
    live = live.reshape(-1)
    keep = jnp.nonzero(live, size=live.size, fill_value=0)[0]
    return x.reshape(-1, x.shape[-1])[keep], y.reshape(-1, y.shape[-1])[keep], live.sum()


def _outcomes(s) -> dict:
    m = s.metrics
    return {"success": np.asarray(m["success"], bool), "coverage": np.asarray(m["coverage"], float),
            "finite": np.asarray(m["finite"], bool)}
