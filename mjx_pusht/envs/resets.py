"""Where the functional env's episodes begin: `reset` from seeds, `reset_to` from given starts, the first state
of a world (`fresh_one`, pure, for the autoreset inside a scan), and `reset_where` for some rows only.

Start poses are drawn on the host from each seed's own generator (task/reset.py), the same on every backend.
"""

from __future__ import annotations

import numpy as np

from mjx_pusht import boundary, validate
from mjx_pusht.api import keyword_checked, keywords
from mjx_pusht.errors import ConfigError
from mjx_pusht.envs import physics as per_episode
from mjx_pusht.envs.starts import START_HI, START_LO, clear_of_tee
from mjx_pusht.envs.state import State
from mjx_pusht.task.controllers import seed_key
from mjx_pusht.task.episode import begin
from mjx_pusht.task.reset import start_poses


@keyword_checked  # every public method: an unknown keyword is one line naming the known ones
class Resets:
    """PushTEnv's resets (a mixin: the env's fields and backend are PushTEnv's)."""

    @keywords  # a missing argument or an unknown keyword: one line naming what it takes
    def reset(self, seeds) -> State:
        """A fresh episode per seed, from the reset distribution's start pose for that seed."""
        seeds = validate.seed_array(seeds)
        if not seeds.size:  # a batch of no worlds (the CLI refuses an empty seed list too)
            raise ConfigError("reset takes one seed per world: got none")
        if self.backend == "cpu":  # its worlds' MjData in this machine's memory, as the vector env's
            from mjx_pusht.boundary import BYTES_PER_CPU_ENV, fits

            fits(f"reset of {len(seeds):,} worlds on the cpu backend", len(seeds), BYTES_PER_CPU_ENV,
                 "reset fewer worlds at once")
        return self.reset_to(start_poses(seeds, reset=self.reset_kind), seeds, drawn=True)

    @keywords  # a missing argument or an unknown keyword: one line naming what it takes
    def reset_to(self, starts, seeds=None, drawn: bool = False) -> State:
        """Episodes from given (N, 5) starts: tee x, y, yaw and pusher x, y (seeds key random controllers).
        A given start (not `drawn` by a reset distribution) must not put the pusher inside the T."""
        if drawn is not True and drawn is not False:  # "yes" was taken as True
            boundary.Flag()("drawn", drawn)
        starts = self._starts(starts) if drawn else self.given_starts(starts)
        seeds = np.zeros(len(starts), np.int64) if seeds is None else validate.seed_array(seeds)
        if len(seeds) != len(starts):
            raise ConfigError(f"seeds: {len(seeds)} seeds for {len(starts)} start states")
        qpos0, key, f = self.layout.initial_qpos(self.model, starts), seed_key(seeds), per_episode.draw(self, seeds)
        if self.backend == "cpu":
            from mjx_pusht.backends.cpu import _Lockstep

            data = _Lockstep(per_episode.cpu_models(self, f), self.model, qpos0, self.episode.frame_skip, self.threads)
            return self._state(data, begin(self.layout, qpos0, key, self._ctrl, self.episode, np), qpos0, key, 0, f)
        import jax.numpy as jnp

        n, dt, f = len(qpos0), self.runner.dtype, f if f is None else f.astype(self.runner.dtype)
        return self._batch_fns(n)[1](self.template(n), jnp.asarray(qpos0, dt), jnp.asarray(key), f)

    def given_starts(self, starts) -> np.ndarray:
        """A user's starts, checked as `_starts` checks any, and the pusher clear of the T (`clear_of_tee`)."""
        return clear_of_tee(self._starts(starts), self.scene.variant)

    def _starts(self, starts) -> np.ndarray:
        """(N, 5) tee x, y, yaw, pusher x, y (or (N, 3) tee only), finite, the positions inside the walls
        (the validation layer's rule; the gym-pusht variant's walls are its own frame's)."""
        try:
            a = np.asarray(starts)
        except ValueError:  # ragged
            raise ConfigError(f"starts must be (N, 5) tee x, y, yaw, pusher x, y, got {starts!r:.60}") from None
        if a.dtype.kind not in "fiu" and a.dtype != object:  # complex lost its imaginary part, bools became 0/1
            raise ConfigError(f"starts must be real numbers, got {a.dtype}")
        try:
            a = np.atleast_2d(a.astype(np.float64))
        except (TypeError, ValueError):
            raise ConfigError(f"starts must be real numbers, got {starts!r:.60}") from None
        if a.ndim == 2 and not len(a):
            raise ConfigError("starts: got no rows; reset_to takes one start per world")
        if a.ndim != 2 or a.shape[1] not in (3, 5):
            raise ConfigError(f"starts must be (N, 5) tee x, y, yaw, pusher x, y (or (N, 3) tee only), got {a.shape}")
        if self.scene.variant != "chapter" or a.shape[1] == 3:  # the tee alone: finite only (its yaw is free)
            if not np.isfinite(a).all():
                raise ConfigError("starts must be finite numbers")
            if self.scene.variant == "gym-pusht":
                _in_gym_pushts_window(a)
            return a
        return validate.starts(a, len(a), START_LO, START_HI)

    def template(self, n: int):
        """The fresh mjx.Data every episode of an `n`-world batch starts from (MJX-Warp sizes its buffers by n)."""
        if n not in self._templates:  # on this process's device: MJX's own default is jax.devices()[0], another
            self._templates[n] = self.runner.initial_data(n, self.runner.devices[0])  # process's under jax.distributed
        return self._templates[n]

    def fresh_one(self, d0, qpos, key, coverage0=None, physics=None) -> State:
        """One world's new episode from `qpos` (pure; no pixels: `with_pixels` adds them). `coverage0`, the
        start's coverage if known, spares the polygon clipping (the costly part of a reset). `physics`: its factors."""
        import jax.numpy as jnp

        carry = begin(self.layout, qpos, key, self._ctrl, self.episode, jnp, coverage0)
        return self._state(d0.replace(qpos=qpos), carry, qpos, key, jnp.zeros((), jnp.int32), physics, pixels=False)

    def _reset_batch(self, d0, q, k, f) -> State:
        import jax

        return jax.vmap(lambda qp, kk, ff: self.with_pixels(self.fresh_one(d0, qp, kk, physics=ff)))(q, k, f)

    def _state(self, data, carry, qpos, key, step, physics=None, pixels=True) -> State:
        xp = self._xp
        ep = carry["ep"]
        obs = self._observe(qpos, data, pixels, goal=carry.get("goal"))
        n = qpos.shape[:-1]
        # an episode that starts covered is terminated at reset, before any step
        dropped = xp.zeros(n, dtype=xp.int32) if self.backend == "mjx-warp" else None
        return State(data, carry, obs, xp.zeros(n, dtype=qpos.dtype), ep["done"] & ep["success"],
                     xp.zeros(n, dtype=bool), xp.zeros(n, dtype=xp.int32) + step, key, dropped, None, physics)

    @keywords  # a missing argument or an unknown keyword: one line naming what it takes
    def reset_where(self, state: State, mask, seeds=None, starts=None) -> State:
        """`state` with the rows where `mask` holds started afresh (from `seeds`' start poses, or `starts`),
        every other row untouched: how a vector env resets the episodes that ended."""
        from mjx_pusht.envs.partial import reset_where

        return reset_where(self, state, mask, seeds, starts)


def _in_gym_pushts_window(a: np.ndarray) -> None:
    """gym-pusht's scene's starts (world frame): the pusher in gym-pusht's 512-pixel window, as the drop-in's
    reset_to_state takes it, and the T's body origin within the window widened by the T's reach (gym-pusht's
    legacy reset puts the origin up to 2 x 45 px from the block position it is given). A start metres away, a
    drop-in's pixels handed to the functional env, was taken (the thirteenth pass)."""
    from mjx_pusht.model import gym_pusht as frame

    origin, _ = frame.pose_to_px(a[:, :3])
    reach = 2 * frame.COG_PX
    bad = ((origin < -reach) | (origin > 512 + reach)).any(axis=1)
    if a.shape[1] == 5:
        agent = frame.to_px(a[:, 3:5])
        bad |= ((agent < -1e-6) | (agent > 512 + 1e-6)).any(axis=1)  # (the round trip from pixels: its rounding)
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise ConfigError(f"starts put a body outside gym-pusht's 512-pixel window (the T's origin within "
                          f"{reach:g} px of it): row {r}, {a[r].tolist()} (world frame, metres and radians; the "
                          "drop-in's reset_to_state takes gym-pusht's pixels)")
