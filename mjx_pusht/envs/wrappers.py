"""Wrappers around the functional env: autoreset on the device, and the pool of start poses it draws from.

    env = AutoReset(PushTEnv(backend="mjx-warp"), mode="same_step")
    state = env.reset(np.arange(4096))                 # pure from here on: jit, scan, vmap-free
    state = jax.lax.scan(lambda s, _: (env.step(s, policy(s.obs)), None), state, None, 1000)[0]

`step` is the env's control step followed, inside the same jitted program, by a `jnp.where` that
replaces only the rows whose episode ended with a new episode (MJX's `Data.where`, which leaves
MJX-Warp's shared contact buffers alone), as Brax's `AutoResetWrapper` and gymnax's `step` do.
The image, if any, is rendered once, after the merge.

Where do the new episodes start? Not from a fixed first state (Brax's choice: every episode of a
row would start the same), and not from a generator run on the device (the task's per-seed
generator is PCG64 in float64, reset.py, which XLA's float32 GPU path cannot reproduce bit for
bit). Instead each row has a queue of its next `depth` episode seeds, drawn on the host by
gymnasium's rule (row i's generator is `np.random.default_rng(seed_i)`, as SyncVectorEnv seeds
its copies), with their start poses and controller keys computed once and held on the device
(`StartPool`). A row's k-th autoreset takes slot k mod depth. `refill` (host) tops the queues up;
the gymnasium vector env calls it every `depth` // 2 steps, so no row ever reuses a slot there.
Inside one long scan, a row that ends more than `depth` episodes repeats its starts from the
first slot: `state.info["used"]` says how many it took, so that is visible, never silent.

The episode that ended is reported in the step that ends it (`mode="same_step"`): its reward,
terminated, truncated, and in `info["final"]` its observation (no image unless `final_pixels`)
and metrics. With `final_pixels` a row that ended needs two images in one step, its last one and its
new episode's first: the step renders all N worlds once, before the merge (the running rows' images
and the ended rows' last ones), and takes each new episode's first image from the pool, where it was
rendered when its start pose was drawn (`info["pool_pixels"]`, (depth, N, size, size, 3) uint8: 3.6 GB
at 16,384 envs and depth 8, in chunks of N // 8 worlds on a renderer of that size). A full render of
N worlds is ~21 ms of a ~60 ms step on an H100 at 16,384 (notebook change 22); a start is rendered
once, at a refill, instead of every row again each step. `image_pool=False` renders twice a step.
`mode="next_step"` is gymnasium's default: the step after the end starts the new episode, ignores
that row's action and reports reward 0, not terminated.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht import boundary
from mjx_pusht import validate
from mjx_pusht.api import keyword_checked, keywords
from mjx_pusht.envs import physics as per_episode
from mjx_pusht.envs.state import check_state
from mjx_pusht.errors import ConfigError
from mjx_pusht.task.controllers import seed_key
from mjx_pusht.task.goals import draw
from mjx_pusht.task.reset import SEED_MAX, start_poses
from mjx_pusht.task.rules import coverage

MODES = ("same_step", "next_step")


@keyword_checked  # every public method: an unknown keyword is one line naming the known ones
class StartPool:
    """Each row's next `depth` episode seeds, their start qpos and keys: host bookkeeping for AutoReset."""

    def __init__(self, env, n: int, depth: int):
        depth = boundary.Int(1, 1 << 20)("the start pool's depth", depth)  # 2.5 was truncated to 2, silently
        self.env, self.n, self.depth = env, int(n), depth
        self.rngs = [np.random.default_rng() for _ in range(self.n)]
        self.seeds = np.zeros((self.depth, self.n), np.int64)  # slot (seq % depth, row)
        self.qpos = np.zeros((self.depth, self.n, env.model.nq), np.float64)
        self.keys = np.zeros((self.depth, self.n, 2), np.uint32)
        self.coverage = np.zeros((self.depth, self.n), np.float64)  # each start's coverage, computed here once
        k = len(env.scenario.randomize)  # each episode's physics factors, drawn from its seed (envs/physics.py)
        self.physics = np.zeros((self.depth, self.n, k), np.float64) if k else None
        # each start's random goal, where its image draws the target (the step draws it again from the key)
        self.goals = None if env.episode.goal is None else np.zeros((self.depth, self.n, 3), np.float64)
        self.dirty = np.ones((self.depth, self.n), bool)  # slots whose start has no image rendered yet
        self.pixels = None  # AutoReset's image pool: each slot's first image, on the device (final_pixels)
        self.filled = np.zeros(self.n, np.int64)  # entries drawn per row (sequence numbers < filled exist)
        self.used = np.zeros(self.n, np.int64)  # entries consumed per row, as of the last refill

    def restart(self, rows, seeds) -> None:
        """Rows `rows` start over: their generators seeded by `seeds` (None: left as they are), queues emptied."""
        for i, s in zip(rows, seeds):
            if s is not None:
                self.rngs[i] = np.random.default_rng(int(s))
        self.filled[rows] = self.used[rows] = 0

    def next_seeds(self, rows) -> np.ndarray:
        """One seed per row in `rows`, drawn now from its generator (a reset without a given seed)."""
        return np.array([int(self.rngs[i].integers(SEED_MAX)) for i in rows], np.int64)

    def refill(self, used) -> bool:
        """Top every row's queue up to `depth` unconsumed entries, given how many each row has consumed."""
        self.used = np.asarray(used, np.int64).copy()
        need = self.used + self.depth - self.filled
        rows = np.flatnonzero(need > 0)
        if not len(rows):
            return False
        seq, row = [], []
        for i in rows:
            for j in range(int(self.filled[i]), int(self.used[i] + self.depth)):
                seq.append(j)
                row.append(i)
        seq, row = np.array(seq), np.array(row)
        seeds = self.next_seeds(row)  # in order per row: each row's generator yields its sequence
        slot = seq % self.depth
        self.seeds[slot, row] = seeds
        qpos = self.env.layout.initial_qpos(self.env.model, start_poses(seeds, reset=self.env.reset_kind))
        self.qpos[slot, row] = qpos
        tee, keys, goal = self.env.layout.tee_pose(qpos), seed_key(seeds), self.env.episode.goal
        # against each episode's goal, which its reset draws from its key (task/goals.py)
        if goal is None:
            self.coverage[slot, row] = coverage(tee)
        else:
            self.goals[slot, row] = goals = draw(keys, goal, np.float64)
            self.coverage[slot, row] = coverage(tee, goals)
        self.keys[slot, row] = keys
        if self.physics is not None:
            self.physics[slot, row] = per_episode.draw(self.env, seeds)
        self.dirty[slot, row] = True
        self.filled[rows] = self.used[rows] + self.depth
        return True

    def arrays(self, xp, dtype) -> dict:
        out = {"pool_qpos": xp.asarray(self.qpos.astype(dtype)), "pool_key": xp.asarray(self.keys),
               "pool_coverage": xp.asarray(self.coverage.astype(dtype))}
        return out if self.physics is None else out | {"pool_physics": xp.asarray(self.physics.astype(dtype))}


@keyword_checked
class AutoReset:
    """Resets the episodes that ended, on the device, inside the step (see the module's docstring)."""

    @keywords  # an unknown keyword: one line naming the known ones
    def __init__(self, env, mode: str = "same_step", depth: int = 8, final_pixels: bool = False,
                 donate: bool = False, image_pool: bool = True):
        boundary.OneOf(tuple(MODES))("autoreset mode", mode)  # an array is refused, not compared
        # None was taken, and failed at the first reset; an AutoReset too (its reset found no model)
        boundary.Instance("mjx_pusht.envs.functional:PushTEnv", "a functional PushTEnv")("AutoReset's env", env)
        # the pool's depth, checked at construction (StartPool checked it only at the first reset: depth=0 was taken)
        self.env, self.mode, self.depth = env, mode, boundary.Int(1, 1 << 20)("AutoReset's depth", depth)
        self.final_pixels = boundary.Flag()("final_pixels", final_pixels)  # "no" was taken as True
        if self.final_pixels and not env.pixels:  # it meant nothing there, and was taken without a word
            raise ConfigError("final_pixels=True keeps an ended episode's last image, but this env draws none "
                              "(PushTEnv(pixels=0)): give the env pixels, or leave final_pixels out")
        # the new episodes' first images from the pool (one render a step), where two would be needed
        self.image_pool = boundary.Flag()("image_pool", image_pool)
        self._put_images: dict = {}
        # the step may reuse the old state's memory (a stateful caller keeps no old state)
        self.donate = boundary.Flag()("donate", donate)
        self.pool: StartPool | None = None
        self._jitted: dict = {}

    # -- host side -----------------------------------------------------------------------------------
    def reset(self, seeds, starts=None, pool: StartPool | None = None):
        """Episodes from `seeds` (or `starts`, (N, 5)), each row's later episodes from its own generator
        seeded by its seed (gymnasium's rule), unless a ready `pool` is given."""
        seeds = np.asarray(seeds, np.int64).reshape(-1)
        state = self.env.reset(seeds) if starts is None else self.env.reset_to(starts, seeds)
        if pool is None:
            pool = StartPool(self.env, len(seeds), self.depth)
            pool.restart(range(len(seeds)), seeds)
        self.pool = pool
        pool.refill(np.zeros(len(seeds), np.int64))
        return self._with_pool(state, np.zeros(len(seeds), np.int32))

    def _with_pool(self, state, used):
        xp = self.env._xp
        dtype = np.float64 if self.env.backend == "cpu" else self.env.runner.dtype
        info = dict(state.info or {}) | self.pool.arrays(xp, dtype) | {"used": xp.asarray(used, dtype=xp.int32)}
        if self._pooled_images():
            info["pool_pixels"] = self._render_pool(len(used))
        info.setdefault("broken", xp.zeros(len(used), dtype=bool))
        info.setdefault("nonfinite_action", xp.zeros(len(used), dtype=bool))  # (in the carry from the first step)
        if self.mode == "same_step" and "final" not in info:
            info["final"] = self._final(state)
        if xp is not np:
            import jax

            # Placed on the state's device as the step's own outputs are: jit keys its compiled programs on
            # whether an input is committed to a device, and arrays made from NumPy are not, so the first step
            # after every reset or refill compiled the whole step (or the user's scan of it) a second time:
            # seconds that change 13's scan benchmark timed as stepping (notebook change 16).
            info = jax.device_put(info, state.step.sharding)
            if "pool_pixels" in info:  # the very array the next refill reuses (donates)
                self.pool.pixels = info["pool_pixels"]
        return state._replace(info=info)

    def _own(self, state, what: str) -> None:
        """`state` from this wrapper's own reset (its start queue's counters), of its batch: one line, not a
        TypeError or AttributeError from the step's insides (a bare env's state, another AutoReset's)."""
        if self.pool is None:
            raise ConfigError(f"AutoReset.{what} before its reset: call reset(seeds) first, and {what} its state")
        # of this env's backend, scene, task and goal (MJX: another task's State was JAX's scan-carry TypeError;
        # refill took it without a word: the thirteenth pass). Shapes and types only: no wait for the device
        check_state(state, self.env.backend, self.env, f"AutoReset.{what}")
        if not isinstance(getattr(state, "info", None), dict) or "used" not in state.info or self.pool.n != len(
                state.step):
            raise ConfigError(f"AutoReset.{what} takes a state from this AutoReset's own reset (of its {self.pool.n} "
                              "rows), not one from the env it wraps or another AutoReset")

    def refill(self, state):
        """Top up every row's start queue (reads `info["used"]` from the device: one small transfer). A row given a
        non-finite action since the reset (held still by the step, on the device) is one line here."""
        self._own(state, "refill")
        bad = state.info.get("nonfinite_action")
        if bad is not None and np.asarray(bad).any():
            raise ConfigError(f"actions must be finite: rows {np.flatnonzero(np.asarray(bad))[:10].tolist()} were given "
                              "a non-finite action since reset (held still, and marked broken)")
        if self.pool.refill(np.asarray(state.info["used"])):
            return self._with_pool(state, state.info["used"])
        return state

    def _pooled_images(self) -> bool:
        """Whether the step takes the new episodes' first images from the pool (same_step, with final images)."""
        return (self.image_pool and self.mode == "same_step" and self.final_pixels and bool(self.env.pixels)
                and self.env.backend != "cpu")

    def _render_pool(self, n: int):
        """The pool's images with every slot drawn since the last call rendered (the rest kept, in place)."""
        import jax
        import jax.numpy as jnp

        pool, size = self.pool, self.env.pixels
        if pool.pixels is None or pool.pixels.shape[:2] != (self.depth, n):
            pool.pixels = jnp.zeros((self.depth, n, size, size, 3), jnp.uint8)
            pool.dirty[:] = True
        slot, row = np.nonzero(pool.dirty)
        if not len(slot):
            return pool.pixels
        m = min(n, max(64, -(-n // 8)))  # a renderer of N // 8 worlds: a refill's new starts are few
        if m not in self._put_images:
            from mjx_pusht.render.pixels import WarpRenderer

            renderer, d0 = WarpRenderer(self.env.model, m, size), self.env.template(m)

            def put(pixels, q, g, s, r):
                images = jax.vmap(lambda qp, gg: renderer(d0.replace(qpos=qp), gg))(q, g)
                return pixels.at[s, r].set(images)

            # the pool's memory is reused (a state from before this refill holds a deleted pool: it fails loudly)
            self._put_images[m] = jax.jit(put, donate_argnums=(0,))
        dtype = self.env.runner.dtype
        for lo in range(0, len(slot), m):  # padded with the chunk's last entry: the same image written twice
            s, r = slot[lo:lo + m], row[lo:lo + m]
            s, r = np.pad(s, (0, m - len(s)), mode="edge"), np.pad(r, (0, m - len(r)), mode="edge")
            q = jnp.asarray(pool.qpos[s, r].astype(dtype))
            g = None if pool.goals is None else jnp.asarray(pool.goals[s, r].astype(dtype))
            pool.pixels = self._put_images[m](pool.pixels, q, g, jnp.asarray(s, jnp.int32), jnp.asarray(r, jnp.int32))
        pool.dirty[:] = False
        return pool.pixels

    # -- the step ------------------------------------------------------------------------------------
    def step(self, state, action):
        self._own(state, "step")
        if self.env.backend == "cpu":
            return self._step_cpu(state, action)
        import jax
        import jax.numpy as jnp

        n = len(state.step)
        if not isinstance(action, jax.Array):  # the caller's own numbers: checked here, as the env's step does (a
            validate.actions_on_device(np.asarray(action), n, np)  # NaN was stepped as 0: the thirteenth pass)
        action = jnp.asarray(action)
        validate.actions_shape_on_device(action, n)  # (n, 2), never reshaped
        self.env._batch_fns(n)  # this batch size's renderer
        if n not in self._jitted:
            self._jitted[n] = jax.jit(self._step_batch, donate_argnums=(1,) if self.donate else ())
        # The image pool goes in beside the state and is put back as it came: an array that a jitted program
        # returns unchanged is copied (3.6 GB a step at 16,384 envs), unless donated
        images = (state.info or {}).get("pool_pixels")
        if images is not None:
            state = state._replace(info={k: v for k, v in state.info.items() if k != "pool_pixels"})
        out = self._jitted[n](self.env.template(n), state, action, images)
        return out if images is None else out._replace(info={**out.info, "pool_pixels": images})

    def _slot(self, info, ended, xp):
        """Each ended row's next queue slot, and the counters after taking it."""
        used = info["used"]
        slot = used % self.depth
        rows = xp.arange(used.shape[0])
        physics = info["pool_physics"][slot, rows] if "pool_physics" in info else None
        return (info["pool_qpos"][slot, rows], info["pool_key"][slot, rows], info["pool_coverage"][slot, rows],
                physics, used + ended.astype(used.dtype))

    def _final(self, stepped):
        """What the ended episode was: obs (image only if asked), metrics and step count."""
        obs = {k: v for k, v in stepped.obs.items() if k != "pixels" or self.final_pixels}
        return {"obs": obs, "metrics": stepped.metrics, "step": stepped.step}

    def _step_batch(self, d0, state, action, images=None):
        import jax
        import jax.numpy as jnp

        env, info = self.env, state.info
        # device actions are looked at on the device (a look from the host would wait for it every step, as the
        # vector env measured): a non-finite row is held still and marked broken, which refill raises on
        nonfinite = ~jnp.all(jnp.isfinite(action), axis=1)
        action = jnp.where(nonfinite[:, None], jnp.zeros_like(action), action)
        stepped = jax.vmap(env.advance_one)(state._replace(info=None), action)  # info's pool is not per world
        if self.mode == "same_step":
            ended = stepped.terminated | stepped.truncated
        else:  # next_step: the rows that ended last step start now, in place of this step; a start on the goal
            # (terminated at reset, step 0) first reports its end in this step, as the env's own step does
            ended = (state.terminated | state.truncated) & (state.step > 0)
        q, k, cov, f, used = self._slot(info, ended, jnp)
        fresh = jax.vmap(lambda qp, kk, c, ff: env.fresh_one(d0, qp, kk, c, ff))(q, k, cov, f)
        out = jax.vmap(_merge)(ended, fresh, stepped)
        new_info, pooled = dict(info), images is not None and self.mode == "same_step"
        if self.mode == "same_step":
            # the step that ended an episode reports it: its reward and flags, its obs in info["final"]
            out = out._replace(reward=stepped.reward, terminated=stepped.terminated, truncated=stepped.truncated)
            if self.final_pixels:  # one render of every world: the running rows' images, the ended rows' last
                stepped = jax.vmap(env.with_pixels)(stepped)
            final = jax.tree.map(lambda a, b: _rows(ended, a, b), self._final(stepped), info["final"])
            new_info = {**new_info, "used": used, "final": final}
            if pooled:  # and the new episodes' first images, rendered when their starts were drawn
                first = images[info["used"] % self.depth, jnp.arange(len(ended))]
                out = out._replace(obs={**out.obs, "pixels": _rows(ended, first, stepped.obs["pixels"])})
        else:
            zero = jnp.zeros_like(stepped.reward)
            out = out._replace(reward=jnp.where(ended, zero, stepped.reward),
                               terminated=jnp.where(ended, False, out.terminated),
                               truncated=jnp.where(ended, False, out.truncated))
            new_info = {**new_info, "used": used}
        # an overflow is kept for the row whatever episode it was in: a dropped contact is never forgotten,
        # and so is a world that went non-finite or left the walls (checked by the caller when it syncs)
        m = stepped.metrics
        new_info["broken"] = info["broken"] | ~(m["finite"] & m["contained"]) | nonfinite
        new_info["nonfinite_action"] = info["nonfinite_action"] | nonfinite
        out = out._replace(dropped=stepped.dropped)
        if not pooled:  # the image after the merge (with final_pixels and no pool: the step's second render)
            out = jax.vmap(env.with_pixels)(out)
        return out._replace(info=new_info)

    def _step_cpu(self, state, action):
        env = self.env
        if self.mode == "next_step":
            ended = np.asarray((state.terminated | state.truncated) & (state.step > 0))
            stepped = env.step(state, action)
        else:
            stepped = env.step(state, action)
            ended = np.asarray(stepped.terminated | stepped.truncated)
        info = state.info
        used = np.asarray(info["used"])
        rows = np.flatnonzero(ended)
        if not len(rows):
            m = stepped.metrics
            return stepped._replace(info={**info, "broken": info["broken"] | ~(m["finite"] & m["contained"])})
        slot = used[rows] % self.depth
        seeds = self.pool.seeds[slot, rows]
        out = env.reset_where(stepped, ended, seeds=seeds)
        new_used = used + ended
        m = stepped.metrics
        new_info = {**info, "used": new_used.astype(np.int32),
                    "broken": info["broken"] | ~(np.asarray(m["finite"]) & np.asarray(m["contained"]))}
        if self.mode == "same_step":
            out = out._replace(reward=stepped.reward, terminated=stepped.terminated, truncated=stepped.truncated)
            import jax

            new_info["final"] = jax.tree.map(lambda a, b: _rows(ended, a, b), self._final(stepped),
                                             info["final"])
        else:
            out = out._replace(reward=np.where(ended, 0.0, stepped.reward),
                               terminated=np.where(ended, False, out.terminated),
                               truncated=np.where(ended, False, out.truncated))
        return out._replace(info=new_info)


def _rows(mask, new, old):
    """Per row: `new` where `mask`, else `old` (arrays of any trailing shape)."""
    xp = np if isinstance(new, np.ndarray) else __import__("jax.numpy", fromlist=["where"])
    m = mask.reshape(mask.shape + (1,) * (new.ndim - mask.ndim))
    return xp.where(m, new, old)


def _merge(ended, fresh, stepped):
    """One world: the fresh episode if its last one ended, else the stepped one (physics via Data.where)."""
    import jax
    import jax.numpy as jnp

    data = stepped.data.where(ended, fresh.data)
    rest = jax.tree.map(lambda a, b: jnp.where(ended, a, b), fresh._replace(data=None, info=None, dropped=None),
                        stepped._replace(data=None, info=None, dropped=None))
    return rest._replace(data=data, info=stepped.info, dropped=stepped.dropped)
