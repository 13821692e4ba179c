"""Controllers that return NaN or infinite actions, for the tests of the check that stops them (test_nonfinite_actions).

`ByKey` picks each row's behaviour by its seed (through the episode's key, so one compiled MJX program serves
every case); `act` is a user's plain `policy(obs, t)` as `--controller bad_actions:act` takes it, set by the
environment: BAD_VALUE (nan, inf, -inf), BAD_STEP (the first control step it is returned at) and BAD_TEE_X (only
the row whose T starts at this x, in metres; unset: every row). Every other action is zero.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import ClassVar

import numpy as np

from mjx_pusht.task.controllers import Controller, seed_key
from mjx_pusht.task.rules import array_namespace

# seed -> (the bad value, the first control step it is returned at); every other seed's actions are zero
CASES = {101: (math.nan, 0), 102: (math.inf, 0), 103: (-math.inf, 0),
         104: (math.nan, 5), 105: (math.inf, 5), 106: (-math.inf, 5)}


@dataclasses.dataclass(frozen=True)
class ByKey(Controller):
    name: str = "bad_actions:ByKey"

    def act(self, carry, obs, t, key):
        xp = array_namespace(obs["state"])
        zero = obs["state"][..., :2] * 0.0
        out = zero
        for seed, (value, step) in CASES.items():
            k = seed_key(np.array([seed]))[0]
            mine = (key[..., 0] == k[0]) & (key[..., 1] == k[1]) & (zero[..., 0] + t >= step)
            out = xp.where(mine[..., None], zero + value, out)
        return out, carry


def act(obs, t):
    xp = array_namespace(obs["state"])
    state = obs["state"]
    zero = state[..., :2] * 0.0
    hit = zero[..., 0] + t >= int(os.environ.get("BAD_STEP", "0"))
    if os.environ.get("BAD_TEE_X"):
        hit = hit & (xp.abs(state[..., 2] - float(os.environ["BAD_TEE_X"])) < 1e-4)
    return xp.where(hit[..., None], zero + float(os.environ.get("BAD_VALUE", "nan")), zero)


@dataclasses.dataclass(frozen=True)
class Looks(Controller):
    """A controller that looks at the top camera's image (so MJX-Warp renders it every step, and runs the rollout
    as a scan of the vmapped step) and returns NaN from control step 2 on."""

    name: str = "bad_actions:Looks"
    pixels: ClassVar[int] = 16

    def act(self, carry, obs, t, key):
        xp = array_namespace(obs["state"])
        zero = obs["state"][..., :2] * 0.0 + xp.mean(obs["pixels"]) * 0.0
        return xp.where((zero[..., 0] + t >= 2)[..., None], zero + math.nan, zero), carry
