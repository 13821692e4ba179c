"""The resume checkpoint of a training run: written whole in a thread (`checkpoint`), read back and checked
against the run's settings (`resume_tree`), restored into DAgger's learner (`restore`); and `TrainError`,
a run that cannot start or resume as asked."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.io.outputs import BackgroundWrite, atomic_write_bytes

# The resume checkpoint holds the whole dataset (8 M samples: ~0.5 GB, ~4 s to write, measured on the H100
# run of notebook change 14), so it is written at most this often, and at the last iteration; a run killed
# between two repeats at most this much work on --resume (the per-iteration policies are written every time).
RESUME_EVERY_S = 60.0
# ... for every RESUME_RING_BYTES of ring: the copy of the ring to the host stops training while it lasts (an
# iteration that wrote one took ~2.7 s longer than its neighbours for an 8 M x 17-float ring, 0.54 GB, in every
# committed 5-minute DAgger curve on the H100), so a ring 4 times larger written as often would stop a 5-minute
# run for ~45 s. Scaled, a checkpoint costs the same ~5% of the wall-clock whatever the ring's size.
RESUME_RING_BYTES = 0.55e9


def resume_every_s(ring_bytes: int) -> float:
    """Seconds between two resume checkpoints of a run whose dataset ring holds `ring_bytes`."""
    return RESUME_EVERY_S * max(1.0, ring_bytes / RESUME_RING_BYTES)


class TrainError(MjxPushtError, ValueError):
    """A training run cannot start or resume as asked; the message says why."""


def config_dict(cfg) -> dict:
    """A method's config (DaggerConfig, PPOConfig) as JSON-ready values: what checkpoints and --resume compare.
    Nested tuples (a `randomize`'s ranges) become lists too, as a checkpoint reads them back."""
    return json.loads(json.dumps(dataclasses.asdict(cfg)))


def checkpoint(path, cfg, learner, iteration, env_steps, curve, writer=None):
    """Everything --resume needs (optimiser, dataset ring, normalisation, curve), written whole. The arrays are
    copied to the host here; writing goes on in a thread while training continues. Returns that thread: join it
    before the next one, and at the end.

    The ring goes to its own file beside `path` (`_ring_file`), its float32 bytes as they are in memory. Inside the
    msgpack (flax's msgpack_serialize), a 32 M-sample ring's writer ran 26 s on a 2-core CPU, and a loop on the main
    thread, which training is between its device calls, ran at 4% of its speed meanwhile: the encoding held the GIL
    (notebook lead7). A raw write lets go of the GIL while the bytes go out. The msgpack holds the rest and names
    the ring's file, written first: a checkpoint on disk always names a whole ring."""
    from flax import serialization

    from mjx_pusht.train.policy import to_numpy

    if writer is not None:
        writer.join()  # one file, written in order
    path = Path(path)
    # this process's own copy of the ring, sliced here: slicing the array held on every process's devices would be a
    # program they all must run, and only the one whose clock says so checkpoints (several processes: run.py)
    x, y = (np.asarray(a[:learner.filled]) for a in learner.spread.own_copy((learner.x, learner.y)))
    ring = _ring_file(path, iteration)
    tree = {"config": json.dumps(config_dict(cfg), sort_keys=True), "iteration": iteration, "env_steps": env_steps,
            "curve": json.dumps(curve), "params": to_numpy(learner.params),
            "opt_state": serialization.to_state_dict(to_numpy(learner.opt_state)),
            "ring": ring.name, "ring_shapes": [list(x.shape), list(y.shape)],
            "head": learner.head, "floor": learner.floor, "norm_mean": learner.norm[0], "norm_std": learner.norm[1]}

    def write():
        atomic_write_bytes(ring, np.ascontiguousarray(x, np.float32), np.ascontiguousarray(y, np.float32))
        atomic_write_bytes(path, serialization.msgpack_serialize(tree))
        for old in path.parent.glob(_ring_file(path, None).name):  # the rings no checkpoint names any more
            if old != ring:
                old.unlink(missing_ok=True)

    writer = BackgroundWrite(write, "resume-checkpoint")
    writer.start()
    return writer


def _ring_file(path: Path, iteration: int | None) -> Path:
    """The dataset ring's file of the checkpoint at `path` written after `iteration` (None: a glob of them all)."""
    return path.with_name(f"{path.stem}-ring-{'*' if iteration is None else f'{iteration:06d}'}.f32")


def _ring(path: Path, tree: dict) -> tuple[np.ndarray, np.ndarray]:
    """The dataset ring (samples, labels) of the checkpoint `tree` read from `path`: from the file it names, or,
    written before the ring had a file of its own, from the tree. A missing or cut file is one line."""
    if "ring" not in tree:
        return np.asarray(tree["x"]), np.asarray(tree["y"])
    shapes = [tuple(int(n) for n in shape) for shape in tree["ring_shapes"]]
    file = path.with_name(tree["ring"])
    try:
        raw = np.fromfile(file, np.float32)
    except OSError as e:
        raise TrainError(f"--resume: the dataset ring {file} is unreadable ({e.strerror or e}); start again without "
                         "--resume") from None
    sizes = [int(np.prod(shape)) for shape in shapes]
    if raw.size != sum(sizes):
        raise TrainError(f"--resume: the dataset ring {file} holds {raw.size} numbers, its checkpoint names "
                         f"{sum(sizes)}; start again without --resume")
    return raw[:sizes[0]].reshape(shapes[0]), raw[sizes[0]:].reshape(shapes[1])


def resume_tree(path: Path, cfg, may_change: tuple[str, ...]) -> dict:
    """The resume checkpoint at `path` (either method's), refused in one line if it is missing, unreadable,
    or from a run with other settings than `cfg` (those in `may_change`, how far to go, excepted)."""
    from flax import serialization

    if not path.is_file():
        raise TrainError(f"--resume: {path} does not exist; nothing to resume (run without --resume to start)")
    try:
        tree = serialization.msgpack_restore(path.read_bytes())
        saved = json.loads(tree["config"])
    except Exception as e:  # noqa: BLE001 - any decoding failure means the same thing to the user
        raise TrainError(f"--resume: {path} is unreadable ({type(e).__name__}); start again without --resume") from None
    now = config_dict(cfg)
    # both keys' sides: another method's run differs in the names of its settings too
    diff = sorted(k for k in set(saved) | set(now) if saved.get(k) != now.get(k) and k not in may_change)
    if diff:
        raise TrainError(f"--resume: the run in {path.parent.parent} was started with other settings "
                         f"({', '.join(diff[:6])}); give the same ones, or a new --out")
    return tree


def restore(path, cfg, learner):
    import jax
    import jax.numpy as jnp
    from flax import serialization

    tree = resume_tree(path, cfg, ("iterations",))
    try:  # the optimiser's layout is this version's: one Adam a part of the network (learner._parts)
        learner.opt_state = serialization.from_state_dict(learner.opt_state, tree["opt_state"])
    except (KeyError, ValueError, TypeError) as e:
        raise TrainError(f"--resume: {path} holds an optimiser state this version does not use ({type(e).__name__}; "
                         "written before the fit's parts had an Adam each?); start again without --resume") from None
    learner.params = jax.tree.map(jnp.asarray, tree["params"])
    x, y = _ring(path, tree)
    n = len(x)
    learner.x = learner.x.at[:n].set(jnp.asarray(x))
    learner.y = learner.y.at[:n].set(jnp.asarray(y))
    learner.filled, learner.head, learner.floor = n, int(tree["head"]), int(tree["floor"])
    learner.norm = (np.asarray(tree["norm_mean"]), np.asarray(tree["norm_std"]))
    curve = json.loads(tree["curve"])
    return int(tree["iteration"]) + 1, int(tree["env_steps"]), curve, curve[-1]["wall_seconds"] if curve else 0.0
