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

Its settings, teacher and seeds are in dagger_config.py (their names importable from here, as before).
"""

from __future__ import annotations

import time
from functools import partial

import numpy as np

from mjx_pusht.train.dagger_config import (ACTION_REF, HELD_OUT_FIRST, LATE_BETA, MEMORY_WEIGHT, RENDER_KEY, TEACHERS,
                                           DaggerConfig, held_out_seeds, student_meta, teacher)
from mjx_pusht.train.policy import features, to_numpy

# DAgger's names as they were before its config had a module of its own
__all__ = ["ACTION_REF", "HELD_OUT_FIRST", "LATE_BETA", "MEMORY_WEIGHT", "RENDER_KEY", "TEACHERS", "DaggerConfig", "Rollouts",
           "held_out_seeds", "student_meta", "teacher"]


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
