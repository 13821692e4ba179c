"""A trained policy: its network, its checkpoint file, and the controller that runs it.

The network is a flax MLP on features of the observation and of the policy's memory (`features`).
It has two heads: the action, squashed by tanh into the servos' ctrlrange (velocity actions, m/s),
and the next memory. The memory is a small discrete state in the expert's own carry format (which
move it is on, and its "near" and "go the long way round" latches, `Expert.act`): the expert
decides with hysteresis, so the present observation alone does not fix its action, and a network
asked to regress it from the observation averages the two choices where they meet (left or right
round the T) into standing still (NOTES, changes 12 and 14). With a memory of its own, trained to
take the expert's next carry, the policy is a function again. Training applies it with flax; the
controller (`PolicyController`, what `--controller policy:PATH` loads) evaluates the same layers
with the array namespace of its input, so one checkpoint runs inside MJX's compiled scan (JAX,
float32) and on MuJoCo C (NumPy, float64) without flax at all. `tests/test_train.py` checks that
both give the training process's actions.

A checkpoint is one file: flax's msgpack serialisation of {"meta": ..., "params": ...}, where
meta says how to read it (format version, obs type, activation, input normalisation) and what made it
(method, iteration, env steps). It is written whole or not at all (temp + rename).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from mjx_pusht.task.controllers import NEAR, REVERSE, Controller, ControllerError
from mjx_pusht.task.rules import CTRL_LIMIT, array_namespace

FORMAT = "mjx_pusht.policy/2"  # /1: one head, the last action as memory (NOTES, change 12)
OBS_TYPES = ("state", "keypoints")
OBS_SIZE = {"state": 5, "keypoints": 16}  # the observations' own widths (what a PPO policy reads)
ACTIVATIONS = ("relu", "silu")


# The memory: the expert's carry (move in the low bits, 0 before the first act; two latch bits).
MOVES = 4  # 0 (none yet), ROTATE, PUSH_X, PUSH_Y
LATCHES = (NEAR, REVERSE)
MEMORY_SIZE = MOVES + len(LATCHES)  # its one-hot / bit encoding in the features
OUTPUTS = 2 + MOVES + len(LATCHES)  # action, move logits, latch logits


def feature_size(obs_type: str) -> int:
    return {"state": 8, "keypoints": 18}[obs_type] + MEMORY_SIZE


def features(obs: dict, obs_type: str, memory):
    """The network's input from an observation dict and the policy's memory, (..., feature_size).

    state: pusher (x, y), tee (x, y), cos and sin of its yaw (the yaw wraps at +-pi; its cosine and
    sine do not), and the pusher in the tee's body frame (where a push meets the T is the question
    a pusher answers, and it is a rotation away from the world frame). keypoints: the T's 8 corners
    and the pusher (x, y). Both end with the memory: its move one-hot, then its two latch bits.
    """
    xp = array_namespace(obs["state"])
    s = obs["state"]
    p = s[..., 0:2]
    memory = xp.astype(memory, xp.int32)
    move = memory & (NEAR - 1)
    mem = [xp.astype(move == k, s.dtype) for k in range(MOVES)] + [xp.astype((memory & b) != 0, s.dtype) for b in LATCHES]
    mem = xp.stack(mem, axis=-1)
    if obs_type == "keypoints":
        return xp.concat([obs["keypoints"], p, mem], axis=-1)
    o, th = s[..., 2:4], s[..., 4]
    c, sn = xp.cos(th), xp.sin(th)
    d = p - o
    body = xp.stack([c * d[..., 0] + sn * d[..., 1], -sn * d[..., 0] + c * d[..., 1]], axis=-1)
    return xp.concat([p, o, xp.stack([c, sn], axis=-1), body, mem], axis=-1)


def decode(head):
    """The network's raw outputs (..., OUTPUTS) -> (velocity action (..., 2), next memory (...,) int32)."""
    xp = array_namespace(head)
    action = xp.tanh(head[..., :2]) * CTRL_LIMIT
    move = xp.astype(xp.argmax(head[..., 2:2 + MOVES], axis=-1), xp.int32)
    for i, bit in enumerate(LATCHES):
        move = move | xp.where(head[..., 2 + MOVES + i] > 0, bit, 0)
    return action, xp.astype(move, xp.int32)


def _activation(name: str, x, xp):
    if name == "relu":
        return xp.maximum(x, 0.0)
    return x / (1.0 + xp.exp(-x))  # silu


def apply(params: dict, meta: dict, x):
    """The network on (..., feature_size) features, in x's array namespace: (action (..., 2), memory (...,))."""
    return decode(_mlp(params, meta, meta["activation"], x))


def apply_ppo(params: dict, meta: dict, obs):
    """A PPO policy (ppo.py) on raw observations (..., obs size): Brax's normalisation, its MLP (silu between
    layers), and its deterministic action, tanh of the Gaussian's location (the first 2 outputs)."""
    return array_namespace(obs).tanh(_mlp(params, meta, "silu", obs)[..., :2]) * CTRL_LIMIT


def _mlp(params: dict, meta: dict, activation: str, x):
    """Normalise by the checkpoint's mean and std, then the Dense layers, in x's array namespace and dtype."""
    xp = array_namespace(x)
    h = (x - xp.asarray(meta["in_mean"], dtype=x.dtype)) / xp.asarray(meta["in_std"], dtype=x.dtype)
    for i in range(len(params)):
        layer = params[f"Dense_{i}"]
        h = h @ xp.asarray(layer["kernel"], dtype=x.dtype) + xp.asarray(layer["bias"], dtype=x.dtype)
        if i < len(params) - 1:
            h = _activation(activation, h, xp)
    return h


def network(hidden: tuple[int, ...], activation: str = "relu"):
    """The flax module training fits: Dense layers named Dense_0.. (what `apply` reads), OUTPUTS outputs."""
    import flax.linen as nn

    act = {"relu": nn.relu, "silu": nn.silu}[activation]

    class MLP(nn.Module):
        @nn.compact
        def __call__(self, x):
            for width in hidden:
                x = act(nn.Dense(width)(x))
            return nn.Dense(OUTPUTS)(x)

    return MLP()


# -- the checkpoint file ----------------------------------------------------------------------------
def save(path: Path, params: dict, meta: dict) -> None:
    """One file, written atomically: a reader sees the previous checkpoint or this one, never half of one."""
    from flax import serialization

    from mjx_pusht.io.outputs import atomic_write_bytes

    tree = {"meta": json.dumps({"format": FORMAT, **meta}, sort_keys=True),
            "params": to_numpy(params)}
    atomic_write_bytes(Path(path), serialization.msgpack_serialize(tree))


def load_checkpoint(path) -> tuple[dict, dict]:
    """(params, meta) of a checkpoint file; a missing, foreign or corrupt file is a one-line ControllerError."""
    from flax import serialization

    path = Path(path)
    if not path.is_file():
        raise ControllerError(f"policy checkpoint {path} does not exist" if not path.exists() else
                              f"policy checkpoint {path} is not a file")
    try:
        tree = serialization.msgpack_restore(path.read_bytes())
        meta = json.loads(tree["meta"])
        params = tree["params"]
    except Exception as e:  # noqa: BLE001 - any decoding failure means the same thing to the user
        raise ControllerError(f"policy checkpoint {path} is not a readable mjx_pusht policy "
                              f"({type(e).__name__}); was it cut short or written by something else?") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ControllerError(f"policy checkpoint {path} has format {meta.get('format') if isinstance(meta, dict) else None!r}; "
                              f"this mjx_pusht reads {FORMAT}")
    _check(path, params, meta)
    return params, meta


def _check(path, params, meta) -> None:
    """The file's layers must chain from the obs type's features to the two heads, and be finite."""
    if meta.get("obs_type") not in OBS_TYPES or meta.get("activation") not in ACTIVATIONS:
        raise ControllerError(f"policy checkpoint {path}: unknown obs type {meta.get('obs_type')!r} or activation "
                              f"{meta.get('activation')!r}")
    ppo = meta.get("method") == "ppo"  # Brax's policy: raw observations in, (loc[, scale]) out, no memory
    width = OBS_SIZE[meta["obs_type"]] if ppo else feature_size(meta["obs_type"])
    if np.shape(meta["in_mean"]) != (width,) or np.shape(meta["in_std"]) != (width,):
        raise ControllerError(f"policy checkpoint {path}: input normalisation is not {width}-wide")
    for i in range(len(params)):
        layer = params.get(f"Dense_{i}")
        kernel = None if layer is None else np.asarray(layer.get("kernel"))
        if kernel is None or kernel.ndim != 2 or kernel.shape[0] != width or np.shape(layer.get("bias")) != kernel.shape[1:]:
            raise ControllerError(f"policy checkpoint {path}: layer Dense_{i} does not take {width} inputs")
        if not (np.isfinite(kernel).all() and np.isfinite(layer["bias"]).all()):
            raise ControllerError(f"policy checkpoint {path}: layer Dense_{i} holds non-finite weights")
        width = kernel.shape[1]
    if ppo and len(params) and width in (2, 4):
        return
    if not len(params) or width != OUTPUTS:
        raise ControllerError(f"policy checkpoint {path}: its layers end in {width} outputs, not {OUTPUTS} "
                              "(an action and a memory)")


def to_numpy(tree):
    """A pytree of device arrays as NumPy arrays (what the checkpoint and the CPU controller hold)."""
    import jax

    return jax.tree.map(np.asarray, tree)


@dataclasses.dataclass(frozen=True, eq=False)
class PolicyController(Controller):
    """A checkpoint as a controller: velocity actions, the same layers in NumPy and in JAX; its carry is its
    memory (int32, 0 at reset, as the expert's)."""

    params: dict | None = None
    meta: dict | None = None

    def act(self, carry, obs, t, key):
        if self.meta.get("method") == "ppo":
            return apply_ppo(self.params, self.meta, obs[self.meta["obs_type"]]), carry
        action, memory = apply(self.params, self.meta, features(obs, self.meta["obs_type"], carry))
        return action, memory


def load_policy(spec: str) -> PolicyController:
    """`policy:PATH` -> the controller that runs the checkpoint at PATH."""
    path = spec.partition(":")[2]
    if not path:
        raise ControllerError("--controller policy:PATH needs the checkpoint's path after 'policy:'")
    params, meta = load_checkpoint(path)
    return PolicyController(name=f"policy:{path}", params=to_numpy(params), meta=meta)

