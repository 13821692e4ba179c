"""DAgger's learner: the student network, its optimisers and the dataset ring, and the jitted fit (minibatch
regression onto the teacher's labels; a pixel student's image reader taught the pose apart)."""

from __future__ import annotations

from functools import partial

import numpy as np

from mjx_pusht.errors import ConfigError
from mjx_pusht.train.dagger import ACTION_REF, MEMORY_WEIGHT, RENDER_KEY, DaggerConfig
from mjx_pusht.train.policy import POSE_SCALE, feature_size, network


# -- the fit: minibatch regression onto the expert's labels ------------------------------------------
class Learner:
    """The student network, its optimisers (one a part of the network, `_parts`) and the dataset ring, held whole on
    every device of `spread` (devices.Spread; None: JAX's default device). A pixel student needs `render`: a jittable
    (n, RENDER_KEY) states -> (n, H, W, 3) uint8 images for n = cfg.image_batch / devices (`PushTEnv.images`), the
    same images its rollouts showed it.

    The fit is data-parallel: one program over the devices (shard_map), each device the loss of its share of every
    minibatch (the same minibatch whatever the device count), the loss differentiated their mean: the gradient of
    the whole minibatch, averaged across devices, one set of weights. So a fit on N devices is the fit on one, up to
    the order of float sums (a test fits the same data on 1 and 2 devices)."""

    def __init__(self, cfg: DaggerConfig, render=None, spread=None):
        import jax
        import jax.numpy as jnp
        import optax

        from mjx_pusht.train.devices import Spread

        if cfg.image and render is None:
            raise ConfigError("a pixel student's Learner needs the env's renderer (PushTEnv.images)")
        self.cfg = cfg
        self.spread = spread = spread or Spread(jax.devices()[:1])
        spread.check(cfg.batch, "--batch")
        if cfg.image:
            spread.check(cfg.image_batch, "--image-batch")
        self.model = network(cfg.hidden, cfg.activation, cfg.image, 2 + cfg.memory.size)
        width = feature_size(cfg.obs_type, cfg.memory, cfg.goal_conditioned)
        image = (jnp.zeros((1, cfg.image, cfg.image, 3), jnp.uint8), jnp.zeros((1, 2))) if cfg.image else ()  # image, pusher
        self._init = lambda key: self.model.init(key, jnp.zeros((1, width)), *image)["params"]
        # Each fit anneals the learning rate from its value to 5% (cosine, restarted every iteration): the
        # policy judged after a fit is then a settled one, not a snapshot of Adam at full step size (measured
        # with a constant rate: held-out success swinging 36-78% between neighbouring iterations, notebook change 14).
        # A pixel student's two parts (the acting layers, the image reader) share no parameters and are fitted apart
        # (`_fit`), each with an Adam of its own annealed over its own steps.
        self.opts = tuple(_adam(cfg.learning_rate, steps, cfg.max_grad_norm) for steps in
                          ((cfg.fit_steps, cfg.reader_steps) if cfg.image else (cfg.fit_steps,)))
        self.start(jax.random.key(cfg.seed))
        self.x, self.y = spread.replicate((jnp.zeros((cfg.max_samples, cfg.sample_width), jnp.float32),
                                           jnp.zeros((cfg.max_samples, 3), jnp.float32)))  # _label: action, memory
        self.filled, self.head, self.floor = 0, 0, 0  # samples held; where the next goes; kept below here
        self.norm = None  # (mean, std) of the features, fixed from the first iteration's data
        self.pose_error_mm = None  # a pixel student's last fit: its pose estimate's RMS error per number, mm
        self.loss_max = None  # the last fit's largest minibatch loss (the actions'): a spike in the fit shows here
        whole = spread.sharding(None)
        self._write = jax.jit(_ring_write, donate_argnums=(0, 1), out_shardings=(whole, whole))
        fit = partial(_fit, self.model, self.opts, cfg.batch, cfg.image_batch, (cfg.fit_steps, cfg.reader_steps),
                      render, cfg.memory, cfg.action_eps, len(spread))
        self._fit = jax.jit(jax.shard_map(fit, mesh=spread.mesh, in_specs=whole.spec, out_specs=whole.spec))

    def start(self, key) -> None:
        """A fresh network from `key` and fresh optimiser states for it."""
        self.params = self._init(key)
        self.opt_state = tuple(opt.init(part) for opt, part in zip(self.opts, _parts(self.params, self.cfg.image)))
        self.place()

    def place(self) -> None:
        """The network, its optimisers' states and the ring whole on every device (after `start`, or a restore)."""
        self.params, self.opt_state = self.spread.replicate((self.params, self.opt_state))
        if hasattr(self, "x"):
            self.x, self.y = self.spread.replicate((self.x, self.y))

    def add(self, x, y, keep: bool = False, n: int | None = None) -> None:
        """Append the first `n` rows of samples `x` and labels `y` (all if None; the rest is padding, as
        `Rollouts.padded` returns them); when the ring is full the oldest student-visited ones go, never those added
        with `keep` (the expert's own demonstrations, iteration 0): measured, a ring that let them go lost the
        student what it had learned as the later, stalled episodes filled it (notebook, change 12)."""
        import jax.numpy as jnp

        x, y = jnp.asarray(x, jnp.float32), jnp.asarray(y, jnp.float32)
        n = len(x) if n is None else n
        if self.norm is None:  # of the features (not of a pixel student's image keys, which come first)
            f = x[:n, RENDER_KEY:] if self.cfg.image else x[:n]
            self.norm = (np.asarray(f.mean(0)), np.asarray(f.std(0)) + 1e-3)
        room = self.cfg.max_samples - self.floor
        if keep:
            room = room // 2  # demonstrations take at most half the ring
        m = min(n, room)  # the last m of the n samples, into the ring from its head on
        self.x, self.y = self._write(self.x, self.y, x, y, *(np.int32(v) for v in (n - m, m, self.head - self.floor,
                                                                                      self.floor)))
        self.filled = min(self.filled + m, self.cfg.max_samples)
        if keep:
            self.floor = self.head = self.filled
        else:
            self.head = self.floor + (self.head - self.floor + m) % (self.cfg.max_samples - self.floor)

    def fit(self, iteration: int, part: int = 0, candidate: int = 0) -> float:
        """One fit of `fit_steps` on the ring; `part` numbers an iteration's fits (DaggerConfig.fits), `candidate`
        the first fit's initialisations (`fit_first`): each draws its own minibatches."""
        import jax
        import jax.numpy as jnp

        norm = tuple(jnp.asarray(a) for a in self.norm)
        key = jax.random.fold_in(jax.random.key(self.cfg.seed + 1), iteration)
        if part:  # the first fit's key as before late fits existed: a run without them is unchanged
            key = jax.random.fold_in(key, part)
        if candidate:  # past any part's number: a candidate never repeats a late fit's minibatches
            key = jax.random.fold_in(key, CANDIDATE_KEYS + candidate)
        # one value for every device of every process (a typed key cannot be put on another process's devices: its
        # bits can)
        args = self.spread.replicate((jnp.int32(self.filled), norm, jax.random.key_data(key)))
        self.params, self.opt_state, loss, pose_mse, loss_max = self._fit(self.params, self.opt_state, self.x, self.y,
                                                                          *args)
        self.loss_max = float(loss_max)
        if self.cfg.image:
            self.pose_error_mm = float(np.sqrt(pose_mse / 4) * POSE_SCALE * 1000)
        return float(loss)

    def fit_first(self, candidates: int, go_on=None) -> tuple[list[float], int]:
        """The first fit (iteration 0) of `candidates` students, each from its own initialisation and minibatches,
        keeping the one whose fit ended at the lowest loss (DaggerConfig.first_fits); returns every candidate's
        loss, in order, and the kept one's number. Candidate 0 is the network and minibatches of a run without the
        setting. `go_on(seconds)`: whether another candidate, taking as long as the last, still fits the budget
        (--minutes: `--first-fits` past it ran on, the budget ignored)."""
        import time

        import jax

        losses, best, took = [], None, 0.0
        for c in range(candidates):
            if c and go_on is not None and not go_on(took):
                break
            t0 = time.perf_counter()
            if c:
                self.start(jax.random.fold_in(jax.random.key(self.cfg.seed), c))
            losses.append(loss := float(self.fit(0, candidate=c)))
            took = time.perf_counter() - t0
            if best is None or (np.isfinite(loss) and not loss >= losses[best[0]]):  # never a NaN over a number
                best = (c, self.params, self.opt_state, self.loss_max, self.pose_error_mm)
        kept, self.params, self.opt_state, self.loss_max, self.pose_error_mm = best
        return losses, kept


def _ring_write(ring_x, ring_y, x, y, first, m, start, floor):
    """Rows first .. first + m of x, y into the ring's rows floor + (start + j) % (ring - floor): one compiled
    program whatever the counts, which are traced numbers (as eager indexing by them, it compiled ~20 small programs
    an iteration, notebook lead7), and the ring updated in place (donated; a copy of a 32 M-sample ring is ~1.8 GB)."""
    import jax.numpy as jnp

    j = jnp.arange(x.shape[0], dtype=jnp.int32) - first
    idx = floor + (start + j) % (ring_x.shape[0] - floor)
    idx = jnp.where((j >= 0) & (j < m), idx, ring_x.shape[0])  # past the ring: dropped
    return ring_x.at[idx].set(x, mode="drop"), ring_y.at[idx].set(y, mode="drop")


# A first-fit candidate's minibatch key folds in this plus its number (`Learner.fit`): above any fit's part number
CANDIDATE_KEYS = 1 << 20


def _adam(learning_rate: float, steps: int, max_grad_norm: float | None = None):
    """Adam whose rate anneals from `learning_rate` to 5% over each `steps` (cosine, restarted every fit), after the
    gradient's global norm is clipped to `max_grad_norm` (None: unclipped)."""
    import optax

    decay = optax.cosine_decay_schedule(learning_rate, steps, alpha=0.05)
    adam = optax.adam(lambda count: decay(count % steps))
    return adam if max_grad_norm is None else optax.chain(optax.clip_by_global_norm(max_grad_norm), adam)


READER = ("Conv_", "Pose_")  # a pixel student's image reader: its layers' names begin so; the acting layers' Dense_


def _parts(params: dict, image: int) -> tuple[dict, ...]:
    """The parameters a fit updates apart: (acting layers, image reader) for a pixel student, else (all,)."""
    if not image:
        return (params,)
    reader = {k: v for k, v in params.items() if k.startswith(READER)}
    return {k: v for k, v in params.items() if k not in reader}, reader


def _fit(model, opts, batch, image_batch, steps, render, fmt, eps, devices, params, opt_state, x, y, filled, norm, bits):
    """Adam steps on minibatches of `batch` samples from the ring; returns the new parameters and optimiser states,
    the loss and (a pixel student) the pose estimate's squared error, each over the last tenth of its steps, and the
    actions' largest minibatch loss over all the steps.
    `steps` is (the actions' steps, the image reader's steps); a state student takes the first.
    Run under shard_map over `devices` devices (Learner): every device draws the same minibatch and takes its own
    contiguous share of it; each loss is the devices' shares' mean (lax.pmean), so its gradient is the minibatch's.

    A pixel student has two parts that share no parameters, fitted one after the other. Its Dense layers learn the
    teacher's action and memory from the *true* pose (`pose_target`: what the image shows), as a state student
    does, in `steps[0]` steps of `batch` samples with no image; then the convolutions and the pose reader learn that
    pose from the first `image_batch` of each of `steps[1]` minibatches, rendered. The student is then "read the
    pose, act on it": at run time the Dense layers get the reader's estimate. Measured on one H100 (notebook change
    25): taught the actions through the images as well, the reader's error grew to ~3 mm (the teacher's labels,
    discontinuous at the mm scale, are not a function of an image, and their averaged gradients blurred what it
    saw) and held-out success stayed at 3-9% for 20 minutes; taught the pose alone, it read to 0.8 mm and the
    student reached 70% in 8 minutes. Fitted apart, the actions need not pay for rendering (~2 ms per 512 images),
    so they can take as many steps as a state student's (notebook change 26). With equal steps the two fits are the
    one-scan, one-Adam fit of change 25 (Adam is elementwise, and neither loss reaches the other part's weights:
    a test checks it)."""
    import jax
    import jax.numpy as jnp
    import optax

    from mjx_pusht.task.rules import CTRL_LIMIT
    from mjx_pusht.train.devices import AXIS
    from mjx_pusht.train.policy import pose_target

    key = jax.random.wrap_key_data(bits)  # the minibatches' key (Learner.fit)

    def imitation(head, yb):
        pred = jnp.tanh(head[:, :2]) * CTRL_LIMIT
        err = jnp.sum((pred - yb[:, :2]) ** 2, axis=-1)
        if eps is not None:  # relative to the label's size above eps, a 0.1 m/s label weighed as before (action_eps)
            err = err * (ACTION_REF**2 + eps**2) / (jnp.sum(yb[:, :2] ** 2, axis=-1) + eps**2)
        mse = jnp.mean(err)
        memory = yb[:, 2].astype(jnp.int32)
        move = optax.softmax_cross_entropy_with_integer_labels(head[:, 2:2 + fmt.moves], fmt.move(memory))
        if fmt.latches:
            bits = jnp.stack(fmt.bits(memory), -1).astype(jnp.float32)
            move = move + optax.sigmoid_binary_cross_entropy(head[:, 2 + fmt.moves:], bits).sum(-1)
        # the memory terms weighted so a wrong move costs what a 0.1 m/s action error does: both matter
        return mse + MEMORY_WEIGHT * jnp.mean(move)

    def minibatch(k, n):
        """This device's share of the first n of `batch` samples drawn from the ring: (features normalised, labels,
        image state or None)."""
        share = n // devices
        idx = jax.lax.dynamic_slice_in_dim(jax.random.randint(k, (batch,), 0, filled), jax.lax.axis_index(AXIS) * share,
                                           share)
        xb, state = x[idx], None
        if render is not None:  # a pixel student's sample: its image's state first, then the features
            state, xb = xb[:, :RENDER_KEY], xb[:, RENDER_KEY:]
        return (xb - norm[0]) / norm[1], y[idx], state

    def acting(p, fixed, k):  # the actions and memory, from the features (and a pixel student's true pose)
        xb, yb, state = minibatch(k, batch)
        if render is None:
            return jax.lax.pmean(imitation(model.apply({"params": p}, xb), yb), AXIS)
        head = model.apply({"params": {**fixed, **p}}, xb, None, state[:, :2], pose_target(state))[0]
        return jax.lax.pmean(imitation(head, yb), AXIS)

    def reading(p, fixed, k):  # a pixel student's pose estimate from the images, against the true pose
        xb, _, state = minibatch(k, image_batch)
        _, pose = model.apply({"params": {**fixed, **p}}, xb, render(state), state[:, :2])
        return jax.lax.pmean(jnp.mean(jnp.sum((pose - pose_target(state)) ** 2, axis=-1)), AXIS)

    def descend(loss_fn, opt, part, state, fixed, n, k):
        def step(c, k):
            p, o = c
            loss, g = jax.value_and_grad(loss_fn)(p, fixed, k)
            updates, o = opt.update(g, o, p)
            return (optax.apply_updates(p, updates), o), loss

        (part, state), losses = jax.lax.scan(step, (part, state), jax.random.split(k, n))
        return part, state, losses[-max(1, n // 10):].mean(), losses.max()

    if render is None:
        params, state, loss, loss_max = descend(acting, opts[0], params, opt_state[0], {}, steps[0], key)
        return params, (state,), loss, jnp.zeros(()), loss_max
    actor, reader = _parts(params, True)
    actor, actor_state, loss, loss_max = descend(acting, opts[0], actor, opt_state[0], reader, steps[0], key)
    # the same key as the actions' minibatches: with equal steps each step shows the reader the first
    # `image_batch` samples of the actions' minibatch, as change 25's one scan did
    reader, reader_state, pose_mse, _ = descend(reading, opts[1], reader, opt_state[1], actor, steps[1], key)
    # the loss reported: the actions' and the pose's (POSE_SCALE units: 2 mm off in each of the 4 numbers is 0.0016,
    # about what a 0.04 m/s action error costs), as change 25's one loss was
    return {**actor, **reader}, (actor_state, reader_state), loss + pose_mse, pose_mse, loss_max
