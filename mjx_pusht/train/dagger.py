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
2.3 ms: NOTES change 21), so a ring of millions of samples costs megabytes, not the tens of GB its images
would.

The student has a memory (policy.py): the expert's carry format, which it carries itself. DAgger's
state is then (observation, memory): the expert labels each visited pair by acting *from the
student's memory* (its `act` is a function of (carry, observation)), giving the action to take and
the memory to keep. So the student is taught the expert's response to the situations its own
memory puts it in, not to situations only the expert's memory would have produced.
"""

from __future__ import annotations

import dataclasses
from functools import partial

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.task.controllers import Expert
from mjx_pusht.train.policy import (
    ACTIVATIONS,
    OBS_TYPES,
    POSE_SCALE,
    feature_size,
    features,
    network,
    to_numpy,
)

MEMORY_WEIGHT = 0.01  # the memory heads' cross-entropy against the actions' squared error (m/s)^2

# The teacher: by default the expert paced for a student ("paced"): its slowest actions faster, its tolerances coarser.
# The expert's turns end at 4 mm/s against the 3.8 mm/s the T's yaw frictionloss needs, its pushes at 61 mm/s against
# 60, and it slows toward a push's start in proportion to the distance left: a student a few mm/s short there does
# not move the T. And it trims to 0.7 mm and 0.006 rad, where the side it pushes from flips with the error's sign:
# a student that cannot tell the sign at that scale averages the two sides into standing still. Either way the
# student's velocity field has a zero there and the pusher settles in it for good: 49 of 64 failed held-out
# episodes of change 17's policy ended so, and 21 of 47 of a student paced only in speed (NOTES change 24). Paced,
# the teacher succeeds as often and sooner (2,048 held-out seeds on MuJoCo C: 99.66% in 86.6 control steps on
# average, the expert 99.46% in 108.6): success (coverage 0.95) comes before those last trims matter.
TEACHERS = {"paced": {"push_min": 0.08, "turn_min": 0.01, "travel_min": 0.06, "pos_tol": 0.002, "yaw_done": 0.015},
            "expert": {}}

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

    def __post_init__(self) -> None:
        if self.obs_type not in OBS_TYPES:
            raise ConfigError(f"DAgger trains from {', '.join(OBS_TYPES)} observations, not {self.obs_type!r}")
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"unknown activation {self.activation!r}; choose from {', '.join(ACTIVATIONS)}")
        for name in ("envs", "iterations", "batch", "fit_steps", "max_samples", "eval_envs", "max_steps", "image_batch",
                     "image_steps"):
            if getattr(self, name) is not None and int(getattr(self, name)) < 1:
                raise ConfigError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(self, name)}")
        if self.envs * self.iterations >= HELD_OUT_FIRST:
            raise ConfigError(f"{self.envs} envs x {self.iterations} iterations would reach the held-out seeds "
                              f"({HELD_OUT_FIRST}+)")
        from mjx_pusht.task.reset import RESETS

        if self.reset not in RESETS[:2]:
            raise ConfigError(f"DAgger trains on the task or chapter reset, not {self.reset!r}")
        if self.teacher not in TEACHERS:
            raise ConfigError(f"unknown teacher {self.teacher!r}; choose from {', '.join(TEACHERS)}")
        if self.image_steps is not None and not self.obs_type.startswith("pixels"):
            raise ConfigError(f"--image-steps teaches a pixel student's image reader; a {self.obs_type} student has none")
        if self.obs_type.startswith("pixels") and self.image_batch > self.batch:
            raise ConfigError(f"--image-batch ({self.image_batch}) must be at most --batch ({self.batch}): it is how "
                              "many of a step's samples are rendered")
        if not 0.0 <= self.beta_decay <= 1.0:
            raise ConfigError(f"--beta-decay must be in [0, 1], got {self.beta_decay}")

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
        return feature_size(self.obs_type) + (RENDER_KEY if self.image else 0)

    def beta(self, iteration: int) -> float:
        return self.beta_decay ** iteration

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

    def __init__(self, env, cfg: DaggerConfig):
        self.env, self.cfg, self.expert = env, cfg, Expert(**TEACHERS[cfg.teacher])
        self._compiled = {}

    def __call__(self, params, norm, seeds, beta, rng: int, learn: int | None = None):
        """Features and expert labels of every live control step of the first `learn` episodes (all if None;
        on the device on MJX), and every episode's outcome. `norm` is (mean, std) of the features; `beta`, the
        expert's share, is one number or one per seed (0 for held-out episodes judged in the same batch)."""
        beta = np.broadcast_to(np.asarray(beta, np.float32), (len(seeds),))
        learn = len(seeds) if learn is None else learn
        if self.env.backend == "cpu":
            return self._cpu(params, norm, seeds, beta, rng, learn)
        return self._mjx(params, norm, seeds, beta, rng, learn)

    def _cpu(self, params, norm, seeds, beta, rng, learn):
        from mjx_pusht.train.policy import apply

        env, cfg = self.env, self.cfg
        meta = {"in_mean": norm[0], "in_std": norm[1], "activation": cfg.activation, "image": cfg.image}
        params = to_numpy(params)
        gen = np.random.default_rng([cfg.seed, rng])
        s = env.reset(seeds)
        memory = self.expert.init(s.key)
        xs, ys = [], []
        for t in range(cfg.max_steps):
            done = np.asarray(s.carry["ep"]["done"])
            if done.all():
                break
            live = ~done
            live[learn:] = False  # judged only: their samples are not learned from
            x = features(s.obs, cfg.obs_type, memory)
            label, label_memory = self.expert.act(memory, s.obs, s.step, s.key)
            student = apply(params, meta, x, s.obs.get("pixels"))
            action, memory = _choose(np, (label, label_memory), student, gen.random(len(seeds)) < beta)
            xs.append(_sample(np, s.obs, x, cfg.image)[live])
            ys.append(_label(np, label, label_memory)[live])
            s = env.step(s, action)
        env.check(s)
        return np.concatenate(xs).astype(np.float32), np.concatenate(ys).astype(np.float32), _outcomes(s)

    def _mjx(self, params, norm, seeds, beta, rng, learn):
        import jax
        import jax.numpy as jnp

        env = self.env
        n = len(seeds)
        s0 = env.reset(seeds)
        if n not in self._compiled:
            self._compiled[n] = jax.jit(self._episodes)
        keys = jax.random.split(jax.random.key(self.cfg.seed * 1_000_003 + rng), n)
        s, x, y, live = self._compiled[n](params, tuple(jnp.asarray(a, jnp.float32) for a in norm), s0,
                                          jnp.asarray(beta), keys)
        env.check(s)
        # (T, N, ...) -> the first `learn` worlds' episodes, one after another
        x, y, live = (jnp.swapaxes(a[:, :learn], 0, 1) for a in (x, y, live))
        keep = jnp.nonzero(live.reshape(-1))[0]  # only the control steps of running episodes
        return (x.reshape(-1, x.shape[-1])[keep], y.reshape(-1, y.shape[-1])[keep], _outcomes(s))

    def _episodes(self, params, norm, s, beta, keys):
        """The batch's episodes: a scan over control steps of the vmapped control step (as the env's own jitted
        step; MJX-Warp's renderer is called per step on the whole batch); stacks (T, N, F), (T, N, 3), (T, N)."""
        import jax
        import jax.numpy as jnp

        from mjx_pusht.train.policy import apply

        cfg = self.cfg
        meta = {"in_mean": norm[0], "in_std": norm[1], "activation": cfg.activation, "image": cfg.image}
        advance = self.env.step_one if cfg.image else self.env.advance_one  # step_one renders the next image

        def one(s, memory, beta, key, t):
            live = ~s.carry["ep"]["done"]
            x = features(s.obs, cfg.obs_type, memory).astype(jnp.float32)
            label, label_memory = self.expert.act(memory, s.obs, s.step, s.key)
            take = jax.random.uniform(jax.random.fold_in(key, t)) < beta
            action, memory = _choose(jnp, (label, label_memory), apply(params, meta, x, s.obs.get("pixels")), take)
            sample = _sample(jnp, s.obs, x, cfg.image)
            return advance(s, action), memory, (sample, _label(jnp, label, label_memory), live)

        def body(c, t):
            s, memory, out = jax.vmap(one, in_axes=(0, 0, 0, 0, None))(*c, beta, keys, t)
            return (s, memory), out

        (s, _), (x, y, live) = jax.lax.scan(body, (s, self.expert.init(s.key)), jnp.arange(cfg.max_steps))
        return s, x, y, live


def _outcomes(s) -> dict:
    m = s.metrics
    return {"success": np.asarray(m["success"], bool), "coverage": np.asarray(m["coverage"], float),
            "finite": np.asarray(m["finite"], bool)}


# -- the fit: minibatch regression onto the expert's labels ------------------------------------------
class Learner:
    """The student network, its optimisers (one a part of the network, `_parts`) and the dataset ring, on the
    default JAX device. A pixel student needs `render`: a jittable (n, RENDER_KEY) states -> (n, H, W, 3) uint8
    images for n = cfg.image_batch (`PushTEnv.images`), the same images its rollouts showed it."""

    def __init__(self, cfg: DaggerConfig, render=None):
        import jax
        import jax.numpy as jnp
        import optax

        if cfg.image and render is None:
            raise ConfigError("a pixel student's Learner needs the env's renderer (PushTEnv.images)")
        self.cfg = cfg
        self.model = network(cfg.hidden, cfg.activation, cfg.image)
        width = feature_size(cfg.obs_type)
        image = (jnp.zeros((1, cfg.image, cfg.image, 3), jnp.uint8), jnp.zeros((1, 2))) if cfg.image else ()  # image, pusher
        self.params = self.model.init(jax.random.key(cfg.seed), jnp.zeros((1, width)), *image)["params"]
        # Each fit anneals the learning rate from its value to 5% (cosine, restarted every iteration): the
        # policy judged after a fit is then a settled one, not a snapshot of Adam at full step size (measured
        # with a constant rate: held-out success swinging 36-78% between neighbouring iterations, NOTES change 14).
        # A pixel student's two parts (the acting layers, the image reader) share no parameters and are fitted apart
        # (`_fit`), each with an Adam of its own annealed over its own steps.
        self.opts = tuple(_adam(cfg.learning_rate, steps) for steps in
                          ((cfg.fit_steps, cfg.reader_steps) if cfg.image else (cfg.fit_steps,)))
        self.opt_state = tuple(opt.init(part) for opt, part in zip(self.opts, _parts(self.params, cfg.image)))
        self.x = jnp.zeros((cfg.max_samples, cfg.sample_width), jnp.float32)
        self.y = jnp.zeros((cfg.max_samples, 3), jnp.float32)  # _label: action, memory
        self.filled, self.head, self.floor = 0, 0, 0  # samples held; where the next goes; kept below here
        self.norm = None  # (mean, std) of the features, fixed from the first iteration's data
        self.pose_error_mm = None  # a pixel student's last fit: its pose estimate's RMS error per number, mm
        self._fit = jax.jit(partial(_fit, self.model, self.opts, cfg.batch, cfg.image_batch,
                                    (cfg.fit_steps, cfg.reader_steps), render))

    def add(self, x, y, keep: bool = False) -> None:
        """Append samples; when the ring is full the oldest student-visited ones go, never those added with
        `keep` (the expert's own demonstrations, iteration 0): measured, a ring that let them go lost the
        student what it had learned as the later, stalled episodes filled it (NOTES, change 12)."""
        import jax.numpy as jnp

        x, y = jnp.asarray(x, jnp.float32), jnp.asarray(y, jnp.float32)
        if self.norm is None:  # of the features (not of a pixel student's image keys, which come first)
            f = x[:, RENDER_KEY:] if self.cfg.image else x
            self.norm = (np.asarray(f.mean(0)), np.asarray(f.std(0)) + 1e-3)
        room = self.cfg.max_samples - self.floor
        if keep:
            room = room // 2  # demonstrations take at most half the ring
        m = min(len(x), room)
        x, y = x[-m:], y[-m:]
        idx = self.floor + (self.head - self.floor + jnp.arange(m)) % (self.cfg.max_samples - self.floor)
        self.x, self.y = self.x.at[idx].set(x), self.y.at[idx].set(y)
        self.filled = min(self.filled + m, self.cfg.max_samples)
        if keep:
            self.floor = self.head = self.filled
        else:
            self.head = self.floor + (self.head - self.floor + m) % (self.cfg.max_samples - self.floor)

    def fit(self, iteration: int) -> float:
        import jax
        import jax.numpy as jnp

        norm = tuple(jnp.asarray(a) for a in self.norm)
        key = jax.random.fold_in(jax.random.key(self.cfg.seed + 1), iteration)
        self.params, self.opt_state, loss, pose_mse = self._fit(self.params, self.opt_state, self.x, self.y,
                                                                jnp.int32(self.filled), norm, key)
        if self.cfg.image:
            self.pose_error_mm = float(np.sqrt(pose_mse / 4) * POSE_SCALE * 1000)
        return float(loss)


def _adam(learning_rate: float, steps: int):
    """Adam whose rate anneals from `learning_rate` to 5% over each `steps` (cosine, restarted every fit)."""
    import optax

    decay = optax.cosine_decay_schedule(learning_rate, steps, alpha=0.05)
    return optax.adam(lambda count: decay(count % steps))


READER = ("Conv_", "Pose_")  # a pixel student's image reader: its layers' names begin so; the acting layers' Dense_


def _parts(params: dict, image: int) -> tuple[dict, ...]:
    """The parameters a fit updates apart: (acting layers, image reader) for a pixel student, else (all,)."""
    if not image:
        return (params,)
    reader = {k: v for k, v in params.items() if k.startswith(READER)}
    return {k: v for k, v in params.items() if k not in reader}, reader


def _fit(model, opts, batch, image_batch, steps, render, params, opt_state, x, y, filled, norm, key):
    """Adam steps on minibatches of `batch` samples from the ring; returns the new parameters and optimiser states,
    the loss and (a pixel student) the pose estimate's squared error, each over the last tenth of its steps.
    `steps` is (the actions' steps, the image reader's steps); a state student takes the first.

    A pixel student has two parts that share no parameters, fitted one after the other. Its Dense layers learn the
    teacher's action and memory from the *true* pose (`pose_target`: what the image shows), as a state student
    does, in `steps[0]` steps of `batch` samples with no image; then the convolutions and the pose reader learn that
    pose from the first `image_batch` of each of `steps[1]` minibatches, rendered. The student is then "read the
    pose, act on it": at run time the Dense layers get the reader's estimate. Measured on one H100 (NOTES change
    25): taught the actions through the images as well, the reader's error grew to ~3 mm (the teacher's labels,
    discontinuous at the mm scale, are not a function of an image, and their averaged gradients blurred what it
    saw) and held-out success stayed at 3-9% for 20 minutes; taught the pose alone, it read to 0.8 mm and the
    student reached 70% in 8 minutes. Fitted apart, the actions need not pay for rendering (~2 ms per 512 images),
    so they can take as many steps as a state student's (NOTES change 26). With equal steps the two fits are the
    one-scan, one-Adam fit of change 25 (Adam is elementwise, and neither loss reaches the other part's weights:
    a test checks it)."""
    import jax
    import jax.numpy as jnp
    import optax

    from mjx_pusht.task.controllers import NEAR
    from mjx_pusht.task.rules import CTRL_LIMIT
    from mjx_pusht.train.policy import LATCHES, MOVES, pose_target

    def imitation(head, yb):
        pred = jnp.tanh(head[:, :2]) * CTRL_LIMIT
        mse = jnp.mean(jnp.sum((pred - yb[:, :2]) ** 2, axis=-1))
        memory = yb[:, 2].astype(jnp.int32)
        move = optax.softmax_cross_entropy_with_integer_labels(head[:, 2:2 + MOVES], memory & (NEAR - 1))
        bits = jnp.stack([(memory & b) != 0 for b in LATCHES], -1).astype(jnp.float32)
        latch = optax.sigmoid_binary_cross_entropy(head[:, 2 + MOVES:], bits).sum(-1)
        # the memory terms weighted so a wrong move costs what a 0.1 m/s action error does: both matter
        return mse + MEMORY_WEIGHT * jnp.mean(move + latch)

    def minibatch(k, n):
        """The first n of `batch` samples drawn from the ring: (features normalised, labels, image state or None)."""
        idx = jax.random.randint(k, (batch,), 0, filled)[:n]
        xb, state = x[idx], None
        if render is not None:  # a pixel student's sample: its image's state first, then the features
            state, xb = xb[:, :RENDER_KEY], xb[:, RENDER_KEY:]
        return (xb - norm[0]) / norm[1], y[idx], state

    def acting(p, fixed, k):  # the actions and memory, from the features (and a pixel student's true pose)
        xb, yb, state = minibatch(k, batch)
        if render is None:
            return imitation(model.apply({"params": p}, xb), yb)
        return imitation(model.apply({"params": {**fixed, **p}}, xb, None, state[:, :2], pose_target(state))[0], yb)

    def reading(p, fixed, k):  # a pixel student's pose estimate from the images, against the true pose
        xb, _, state = minibatch(k, image_batch)
        _, pose = model.apply({"params": {**fixed, **p}}, xb, render(state), state[:, :2])
        return jnp.mean(jnp.sum((pose - pose_target(state)) ** 2, axis=-1))

    def descend(loss_fn, opt, part, state, fixed, n, k):
        def step(c, k):
            p, o = c
            loss, g = jax.value_and_grad(loss_fn)(p, fixed, k)
            updates, o = opt.update(g, o, p)
            return (optax.apply_updates(p, updates), o), loss

        (part, state), losses = jax.lax.scan(step, (part, state), jax.random.split(k, n))
        return part, state, losses[-max(1, n // 10):].mean()

    if render is None:
        params, state, loss = descend(acting, opts[0], params, opt_state[0], {}, steps[0], key)
        return params, (state,), loss, jnp.zeros(())
    actor, reader = _parts(params, True)
    actor, actor_state, loss = descend(acting, opts[0], actor, opt_state[0], reader, steps[0], key)
    # the same key as the actions' minibatches: with equal steps each step shows the reader the first
    # `image_batch` samples of the actions' minibatch, as change 25's one scan did
    reader, reader_state, pose_mse = descend(reading, opts[1], reader, opt_state[1], actor, steps[1], key)
    # the loss reported: the actions' and the pose's (POSE_SCALE units: 2 mm off in each of the 4 numbers is 0.0016,
    # about what a 0.04 m/s action error costs), as change 25's one loss was
    return {**actor, **reader}, (actor_state, reader_state), loss + pose_mse, pose_mse
