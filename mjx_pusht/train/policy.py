"""A trained policy: its network, its checkpoint file, and the controller that runs it.

The network is a flax MLP on features of the observation and of the policy's memory (`features`).
It has two heads: the action, squashed by tanh into the servos' ctrlrange (velocity actions, m/s),
and the next memory. The memory is a small discrete state in the expert's own carry format (which
move it is on, and its "near" and "go the long way round" latches, `Expert.act`): the expert
decides with hysteresis, so the present observation alone does not fix its action, and a network
asked to regress it from the observation averages the two choices where they meet (left or right
round the T) into standing still (notebook, changes 12 and 14). With a memory of its own, trained to
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

from mjx_pusht.task.controllers import Controller, ControllerError
from mjx_pusht.task.goals import goal_features
from mjx_pusht.task.memory import CHAPTER, CarryFormat
from mjx_pusht.task.rules import CTRL_LIMIT, array_namespace
from mjx_pusht.train.layers import activation as _activation
from mjx_pusht.train.layers import mlp as _mlp
from mjx_pusht.train.layers import rowwise as _rowwise
from mjx_pusht.train.ppo_policy import apply_ppo, ppo_input

FORMAT = "mjx_pusht.policy/2"  # /1: one head, the last action as memory (notebook, change 12)
OBS_TYPES = ("state", "keypoints", "pixels_agent_pos")
OBS_SIZE = {"state": 5, "keypoints": 16}  # the observations' own widths (what a PPO policy reads)
ACTIVATIONS = ("relu", "silu")
PPO_ACTS = ("mean", "sample")  # a PPO policy's action: its Gaussian's mean, or a draw keyed by seed and step
# A pixel policy's image trunk: 3x3 convolutions of stride 2, no padding (96 -> 47 -> 23 -> 11 -> 5 pixels),
# then the flattened 5 x 5 x 32 map is read into the T's pose by two Dense layers (Pose_0, Pose_1), and the policy
# acts on that estimate as a state policy acts on the true pose (`pose_features`). Training teaches the reader the
# true pose from the images and the Dense layers the teacher's actions from the true pose (train/dagger.py `_fit`).
# Before, the flattened map joined the Dense layers directly, taught by the actions alone: 3.6% held-out success
# after 18 minutes on an H100, where this reaches 70% in 8; a spatial softmax over a 19 x 19 map did no better
# (notebook changes 21, 25).
CONV_CHANNELS = (32, 32, 32, 32)
CONV_KERNEL, CONV_STRIDE = 3, 2
POSE_HIDDEN = 256
# The pose as 4 numbers in metres: the T's origin (x, y) and its yaw as the point LEVER metres along the bar from
# it (LEVER cos, LEVER sin), so an error in either reads as a distance; the network's are in POSE_SCALE units.
LEVER = 0.06  # the bar's half-length (rules.T_RECTS)
POSE_SCALE = 0.1


# The memory: the teacher's carry, in its format (task/memory.py). The chapter expert's, the default and what a
# checkpoint without a "memory" entry holds: move in the low bits (0 before the first act), two latch bits.
MOVES = CHAPTER.moves  # 0 (none yet), ROTATE, PUSH_X, PUSH_Y
LATCHES = CHAPTER.latches  # NEAR, REVERSE
MEMORY_SIZE = CHAPTER.size  # its one-hot / bit encoding in the features
OUTPUTS = 2 + CHAPTER.size  # action, move logits, latch logits


GOAL_FEATURES = {"state": 8, "keypoints": 16}  # a goal-conditioned policy's goal features (`features`)


def feature_size(obs_type: str, fmt: CarryFormat = CHAPTER, goal: bool = False) -> int:
    """The width of `features` (a pixel policy's features are what it reads beside the image; `goal`: a
    goal-conditioned policy's, its goal's features added)."""
    return {"state": 8, "keypoints": 18, "pixels_agent_pos": 2}[obs_type] + fmt.size + (
        GOAL_FEATURES[obs_type] if goal else 0)


def conv_out(size: int) -> int:
    """The image trunk's output side for a size x size input."""
    for _ in CONV_CHANNELS:
        size = (size - CONV_KERNEL) // CONV_STRIDE + 1
    return size


def features(obs: dict, obs_type: str, memory, fmt: CarryFormat = CHAPTER, goal: bool = False):
    """The network's input from an observation dict and the policy's memory, (..., feature_size).

    state: pusher (x, y), tee (x, y), cos and sin of its yaw (the yaw wraps at +-pi; its cosine and
    sine do not), and the pusher in the tee's body frame (where a push meets the T is the question
    a pusher answers, and it is a rotation away from the world frame). keypoints: the T's 8 corners
    and the pusher (x, y). pixels_agent_pos: the pusher (x, y) only (the T is in the image, read by
    `apply`'s convolutions). `goal` (a goal-conditioned policy, obs["goal"]): then the goal's (x, y), the cosine and
    sine of its yaw, the T's offset from it in its frame and the cosine and sine of the T's yaw from it (state), or
    the goal T's 8 corners (keypoints). All end with the memory in `fmt`: its move one-hot, then its latch bits.
    """
    xp = array_namespace(obs["state"])
    s = obs["state"]
    p = s[..., 0:2]
    mem = fmt.encode(memory, s.dtype)
    if goal:
        mem = xp.concat([goal_features(obs, obs_type), mem], axis=-1)
    if obs_type == "keypoints":
        return xp.concat([obs["keypoints"], p, mem], axis=-1)
    if obs_type == "pixels_agent_pos":
        return xp.concat([p, mem], axis=-1)
    o, th = s[..., 2:4], s[..., 4]
    c, sn = xp.cos(th), xp.sin(th)
    d = p - o
    body = xp.stack([c * d[..., 0] + sn * d[..., 1], -sn * d[..., 0] + c * d[..., 1]], axis=-1)
    return xp.concat([p, o, xp.stack([c, sn], axis=-1), body, mem], axis=-1)


def decode(head, fmt: CarryFormat = CHAPTER):
    """The network's raw outputs (..., 2 + fmt.size) -> (velocity action (..., 2), next memory (...,) int32)."""
    xp = array_namespace(head)
    return xp.tanh(head[..., :2]) * CTRL_LIMIT, fmt.carry(head[..., 2:])


def apply(params: dict, meta: dict, x, image=None):
    """The network on (..., feature_size) features (and, for a pixel policy, the (..., H, W, 3) uint8 image), in
    x's array namespace: (action (..., 2), memory (...,)). In NumPy a row's result does not depend on the rows
    beside it (`_rowwise`)."""
    act, fmt = meta["activation"], CarryFormat.of(meta)
    if meta.get("image"):
        def dense(v, h):  # the reader's Dense layers and the acting layers, on features and flattened maps
            return decode(_mlp(params, meta, act, v, pose_features(_pose_head(params, act, h), v[..., :2])), fmt)

        return _rowwise(dense, x, _trunk(params, act, image, x.dtype))
    return _rowwise(lambda v: decode(_mlp(params, meta, act, v), fmt), x)


def pose_target(state):
    """The pose a pixel policy is taught to read from the image: (..., 4) in POSE_SCALE units, from (..., 5)
    observation states (pusher x, y, tee x, y, yaw)."""
    xp = array_namespace(state)
    th = state[..., 4]
    return xp.stack([state[..., 2], state[..., 3], LEVER * xp.cos(th), LEVER * xp.sin(th)], axis=-1) / POSE_SCALE


def pose_features(pose, pusher):
    """What a pixel policy's Dense layers read of a pose estimate (..., 4, POSE_SCALE units) and the pusher's
    position (..., 2, metres): the state features' tee terms (`features`: its position, the cosine and sine of its
    yaw, the pusher in its body frame), lengths in POSE_SCALE units."""
    xp = array_namespace(pose)
    r = xp.sqrt(pose[..., 2] ** 2 + pose[..., 3] ** 2 + 1e-12)
    c, sn = pose[..., 2] / r, pose[..., 3] / r
    d = pusher / POSE_SCALE - pose[..., :2]
    body = xp.stack([c * d[..., 0] + sn * d[..., 1], -sn * d[..., 0] + c * d[..., 1]], axis=-1)
    return xp.concat([pose[..., :2], xp.stack([c, sn], axis=-1), body], axis=-1)


def read_pose(params: dict, activation: str, image, dtype):
    """A pixel policy's estimate of the T's pose from (..., H, W, 3) uint8 images: (..., 4), POSE_SCALE units."""
    return _pose_head(params, activation, _trunk(params, activation, image, dtype))


def _pose_head(params: dict, activation: str, h):
    """The reader's two Dense layers on the trunk's flattened maps (..., 800): the pose, (..., 4)."""
    xp = array_namespace(h)
    for i in range(2):
        layer = params[f"Pose_{i}"]
        h = h @ xp.asarray(layer["kernel"], dtype=h.dtype) + xp.asarray(layer["bias"], dtype=h.dtype)
        h = _activation(activation, h, xp) if i == 0 else h
    return h


def _trunk(params: dict, activation: str, image, dtype):
    """The image trunk in the image's array namespace: (..., H, W, 3) uint8 -> (..., flattened map).

    A convolution of stride s without padding is, per kernel offset (a, b), the input's strided slice
    starting at (a, b) times that offset's (in, out) kernel matrix; summed over offsets that is exactly
    flax's `nn.Conv(padding="VALID")`, written in slices and matmuls so NumPy runs it as flax does. JAX runs
    XLA's own convolution instead: the slices' partial sums of a 4,096-image batch asked an H100 for 19.6 GiB
    in DAgger's rollout (notebook change 21)."""
    xp = array_namespace(image)
    h = xp.astype(image, dtype) / 255.0 - 0.5
    for i in range(len(CONV_CHANNELS)):
        layer = params[f"Conv_{i}"]
        kernel, bias = xp.asarray(layer["kernel"], dtype=dtype), xp.asarray(layer["bias"], dtype=dtype)
        if xp.__name__.startswith("jax"):
            acc = _conv_xla(h, kernel) + bias
        else:
            side = (h.shape[-2] - CONV_KERNEL) // CONV_STRIDE + 1
            span = CONV_STRIDE * (side - 1) + 1
            acc = bias
            for a in range(CONV_KERNEL):
                for b in range(CONV_KERNEL):
                    acc = acc + h[..., a:a + span:CONV_STRIDE, b:b + span:CONV_STRIDE, :] @ kernel[a, b]
        h = _activation(activation, acc, xp)
    return xp.reshape(h, h.shape[:-3] + (-1,))


def _conv_xla(h, kernel):
    """flax's `nn.Conv(padding="VALID", strides=CONV_STRIDE)` on (..., H, W, C) in JAX, leading axes folded."""
    from jax import lax

    lead = h.shape[:-3]
    out = lax.conv_general_dilated(h.reshape((-1,) + h.shape[-3:]), kernel, (CONV_STRIDE, CONV_STRIDE), "VALID",
                                   dimension_numbers=("NHWC", "HWIO", "NHWC"))
    return out.reshape(lead + out.shape[1:])


def network(hidden: tuple[int, ...], activation: str = "relu", image: int = 0, outputs: int = OUTPUTS):
    """The flax module training fits: Dense layers named Dense_0.. (what `apply` reads), `outputs` outputs. With
    `image` (its side in pixels): the convolutions Conv_0.. and the pose reader Pose_0, Pose_1 first, called as
    module(normalised features, image, pusher position in metres) -> (outputs, pose estimate); given a `pose`
    (POSE_SCALE units) instead of an image, the Dense layers act on that pose (training's true-pose part)."""
    import flax.linen as nn
    import jax.numpy as jnp

    act = {"relu": nn.relu, "silu": nn.silu}[activation]

    class MLP(nn.Module):
        @nn.compact
        def __call__(self, x, img=None, pusher=None, pose=None):
            if image and pose is None:
                h = img.astype(x.dtype) / 255.0 - 0.5
                for ch in CONV_CHANNELS:
                    h = act(nn.Conv(ch, (CONV_KERNEL, CONV_KERNEL), strides=(CONV_STRIDE, CONV_STRIDE),
                                    padding="VALID")(h))
                h = act(nn.Dense(POSE_HIDDEN, name="Pose_0")(h.reshape(h.shape[:-3] + (-1,))))
                pose = nn.Dense(4, name="Pose_1")(h)
            if image:
                x = jnp.concatenate([pose_features(pose, pusher), x], axis=-1)
            for i, width in enumerate(hidden):
                x = act(nn.Dense(width, name=f"Dense_{i}")(x))
            out = nn.Dense(outputs, name=f"Dense_{len(hidden)}")(x)
            return (out, pose) if image else out

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
    try:  # missing, a folder, unreadable, or a name too long for the filesystem (is_file raised that one)
        data = path.read_bytes()
    except OSError as e:
        why = {FileNotFoundError: "does not exist", IsADirectoryError: "is not a file"}
        raise ControllerError(f"policy checkpoint {path} {why.get(type(e), f'cannot be read: {e.strerror}')}") from None
    try:
        tree = serialization.msgpack_restore(data)
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


def _numbers(path, what: str, value, shape=None) -> np.ndarray:
    """`value` as finite float64 numbers (of `shape`, if given): a string, a nested dict or a ragged list in a file
    is one line naming what holds it, never NumPy's "could not convert string to float"."""
    try:
        a = np.asarray(value)
        if a.dtype.kind not in "biuf":  # strings, objects, complex: not weights
            raise TypeError
        a = a.astype(np.float64)
    except (TypeError, ValueError):
        raise ControllerError(f"policy checkpoint {path}: {what} holds something other than numbers "
                              f"({type(value).__name__})") from None
    if shape is not None and a.shape != shape:
        raise ControllerError(f"policy checkpoint {path}: {what} has shape {a.shape}, not {shape}")
    if not np.isfinite(a).all():
        raise ControllerError(f"policy checkpoint {path}: {what} holds non-finite values")
    return a


def _check(path, params, meta) -> None:
    """The file's layers must chain from the obs type's features to the two heads, be numbers, and be finite."""
    if not isinstance(params, dict) or not all(isinstance(v, dict) for v in params.values()):
        raise ControllerError(f"policy checkpoint {path}: its params are not named layers of weights")
    obs_type, activation = meta.get("obs_type"), meta.get("activation")
    if not (isinstance(obs_type, str) and obs_type in OBS_TYPES and isinstance(activation, str)
            and activation in ACTIVATIONS):
        raise ControllerError(f"policy checkpoint {path}: unknown obs type {obs_type!r} or activation {activation!r}")
    image = meta.get("image", 0)
    pixels = obs_type.startswith("pixels")
    if isinstance(image, bool) or not isinstance(image, int) or pixels != bool(image) or (
            pixels and not (image <= 2048 and conv_out(image) >= 1)):
        raise ControllerError(f"policy checkpoint {path}: a {obs_type} policy with image size {image!r}")
    ppo = meta.get("method") == "ppo"  # Brax's policy: raw observations in, (loc[, scale]) out, no memory
    fmt = _memory_format(path, meta)
    goal = meta.get("goal", False)  # a goal-conditioned policy (DAgger --goal random); absent: the fixed goal's
    if not isinstance(goal, bool) or (goal and (ppo or obs_type not in GOAL_FEATURES)):
        raise ControllerError(f"policy checkpoint {path}: goal {goal!r} for a {obs_type} policy")
    width = OBS_SIZE[obs_type] if ppo else feature_size(obs_type, fmt, goal)
    if ppo and not (isinstance(meta.get("act", "mean"), str) and meta.get("act", "mean") in PPO_ACTS):
        raise ControllerError(f"policy checkpoint {path}: unknown PPO action {meta.get('act')!r} (mean or sample)")
    _numbers(path, "input normalisation in_mean", meta.get("in_mean"), (width,))
    if (_numbers(path, "input normalisation in_std", meta.get("in_std"), (width,)) <= 0).any():
        raise ControllerError(f"policy checkpoint {path}: input normalisation in_std must be positive (it divides)")
    if image:  # the trunk's layers chain from 3 colours to the map the pose reader reads, its pose to the Dense layers
        channels = 3
        for i in range(len(CONV_CHANNELS)):
            layer = params.get(f"Conv_{i}") or {}
            if np.shape(layer.get("kernel")) != (CONV_KERNEL, CONV_KERNEL, channels, CONV_CHANNELS[i]):
                raise ControllerError(f"policy checkpoint {path}: layer Conv_{i} is not this version's image trunk")
            _numbers(path, f"layer Conv_{i}'s kernel", layer["kernel"])
            _numbers(path, f"layer Conv_{i}'s bias", layer.get("bias"), (CONV_CHANNELS[i],))
            channels = CONV_CHANNELS[i]
        pose_in = conv_out(image) ** 2 * channels
        for i, shape in enumerate(((pose_in, POSE_HIDDEN), (POSE_HIDDEN, 4))):
            layer = params.get(f"Pose_{i}") or {}
            if np.shape(layer.get("kernel")) != shape or np.shape(layer.get("bias")) != shape[1:]:
                raise ControllerError(f"policy checkpoint {path}: layer Pose_{i} is not this version's pose reader")
            _numbers(path, f"layer Pose_{i}'s weights", layer["kernel"])
            _numbers(path, f"layer Pose_{i}'s weights", layer["bias"])
        width += len(pose_features(np.zeros(4), np.zeros(2)))
    dense = [k for k in params if k.startswith("Dense_")]
    for i in range(len(dense)):
        layer = params.get(f"Dense_{i}")
        kernel = None if layer is None else np.asarray(layer.get("kernel"))
        if kernel is None or kernel.ndim != 2 or kernel.shape[0] != width or np.shape(layer.get("bias")) != kernel.shape[1:]:
            raise ControllerError(f"policy checkpoint {path}: layer Dense_{i} does not take {width} inputs")
        _numbers(path, f"layer Dense_{i}'s weights", kernel)
        _numbers(path, f"layer Dense_{i}'s weights", layer["bias"])
        width = kernel.shape[1]
    if ppo and len(dense) and (width == 4 or (width == 2 and meta.get("act", "mean") == "mean")):
        return
    if not len(dense) or width != 2 + fmt.size:
        raise ControllerError(f"policy checkpoint {path}: its layers end in {width} outputs, not {2 + fmt.size} "
                              "(an action and a memory)")


def _memory_format(path, meta) -> CarryFormat:
    """The memory's format a checkpoint names (the chapter's where it names none), checked to be one."""
    try:
        fmt = CarryFormat.of(meta)
        ok = 1 <= fmt.moves <= 4096 and len(fmt.latches) <= 8 and all(b > 0 and b & (b - 1) == 0 for b in fmt.latches)
    except (TypeError, ValueError, KeyError, AttributeError):
        ok = False
    if not ok:
        raise ControllerError(f"policy checkpoint {path}: its memory format {meta.get('memory')!r} is not one "
                              "(moves, latch bits, offset)")
    return fmt


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

    @property
    def pixels(self) -> int:
        """The side of the top-camera image it looks at (obs["pixels"], rendered by the backend); 0: none."""
        return int(self.meta.get("image", 0))

    @property
    def reads_goal(self) -> bool:  # else, on random goals, it sees them from the goal's frame (task/goals.GoalFrame)
        return bool(self.meta.get("goal", False))

    def init(self, key):
        """Its memory at reset: its teacher's carry at reset, move class 0 (gym-pusht's expert's -1: no contact yet;
        a 0 there would read as pursuing contact 0, a memory the student never had at a start)."""
        return super().init(key) - CarryFormat.of(self.meta).offset

    def act(self, carry, obs, t, key):
        if self.meta.get("method") == "ppo":
            return apply_ppo(self.params, self.meta, ppo_input(self.meta, obs), key, t), carry
        x = features(obs, self.meta["obs_type"], carry, CarryFormat.of(self.meta), self.reads_goal)
        action, memory = apply(self.params, self.meta, x, obs.get("pixels"))
        return action, memory


def load_policy(spec: str) -> PolicyController:
    """`policy:PATH` -> the controller that runs the checkpoint at PATH."""
    path = spec.partition(":")[2]
    if not path:
        raise ControllerError("--controller policy:PATH needs the checkpoint's path after 'policy:'")
    params, meta = load_checkpoint(path)
    return PolicyController(name=f"policy:{path}", params=to_numpy(params), meta=meta)

