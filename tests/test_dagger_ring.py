"""DAgger's dataset ring: what a rollout's samples do to it, against a plain list written from its rules, and that
adding them compiles nothing after the first iteration, however long the episodes ran (notebook lead7: the count
of samples was a new shape every iteration, ~20 small programs compiled each, ~1 s of an iteration on a GPU)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("flax")
pytest.importorskip("optax")


def _rows(rng, n, width, start):
    """n samples whose first number names them (start, start + 1, ...), the rest noise; labels likewise."""
    x = np.column_stack([np.arange(start, start + n), rng.normal(size=(n, width - 1))]).astype(np.float32)
    y = np.column_stack([np.arange(start, start + n), rng.normal(size=(n, 2))]).astype(np.float32)
    return x, y


class _ListRing:
    """The ring's rules, written as a list: iteration 0's samples (the expert's demonstrations) are kept for good
    and take at most half the ring (the newest of them if more came); later samples fill the rest, and once it is
    full each newcomer replaces the oldest student sample."""

    def __init__(self, size):
        self.size, self.kept, self.student = size, [], []

    def add(self, names, keep):
        if keep:
            self.kept = list(names[len(names) - min(len(names), self.size // 2):])
        else:
            self.student = (self.student + list(names))[-(self.size - len(self.kept)):]

    def names(self):
        return set(self.kept) | set(self.student)


def test_the_ring_keeps_the_demonstrations_and_replaces_the_oldest_student_samples_first():
    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.learner import Learner

    rng = np.random.default_rng(0)
    cfg = DaggerConfig(hidden=(8,), max_samples=1000)
    learner, ring, start = Learner(cfg), _ListRing(1000), 0
    # the demonstrations overflow half the ring; then student batches that wrap the ring several times, one
    # smaller than the padding it comes with (n of the rows), one larger than the ring's free part
    for i, (n, pad) in enumerate([(700, 0), (120, 0), (333, 200), (90, 500), (811, 0), (5, 0), (640, 17)]):
        x, y = _rows(rng, n + pad, cfg.sample_width, start)
        learner.add(x, y, keep=i == 0, n=n)
        ring.add(range(start, start + n), keep=i == 0)
        start += n + pad
        held = np.asarray(learner.x[:learner.filled, 0]).astype(int)
        assert learner.filled == min(sum(len(v) for v in (ring.kept, ring.student)), 1000)
        assert set(held) == ring.names(), i
        # each row's label is its own sample's, and the demonstrations sit below the floor
        assert np.array_equal(np.asarray(learner.y[:learner.filled, 0]).astype(int), held)
        assert set(held[:learner.floor]) == set(ring.kept)


def test_a_rollouts_samples_are_compacted_episode_after_episode_with_padding_that_repeats_the_first():
    """`_compact` (Rollouts on MJX): the first `learn` worlds' live control steps, episode after episode, as numpy
    would pick them, their count, and padding rows that repeat the first sample (so a finiteness check of the whole
    array checks exactly the samples)."""
    import jax

    from mjx_pusht.train.dagger import _compact

    rng = np.random.default_rng(1)
    steps, worlds, learn = 12, 9, 6
    x = rng.normal(size=(steps, worlds, 4)).astype(np.float32)
    y = rng.normal(size=(steps, worlds, 3)).astype(np.float32)
    ends = rng.integers(1, steps + 1, worlds)
    live = np.arange(steps)[:, None] < ends[None, :]
    got_x, got_y, n = jax.jit(lambda *a: _compact(*a, learn=learn))(x, y, live)
    want_x = np.concatenate([x[: ends[w], w] for w in range(learn)])
    want_y = np.concatenate([y[: ends[w], w] for w in range(learn)])
    assert int(n) == int(ends[:learn].sum()) and got_x.shape == (steps * learn, 4)
    assert np.array_equal(np.asarray(got_x)[: int(n)], want_x) and np.array_equal(np.asarray(got_y)[: int(n)], want_y)
    assert (np.asarray(got_x)[int(n):] == x[0, 0]).all()


def test_adding_a_rollouts_samples_compiles_nothing_after_the_first_iteration():
    """Rollouts on MJX and the ring: batches of different counts (as episodes end at different steps) go through
    the same compiled programs; only the first iteration compiles (its normalisation and the ring's write). Counted
    from JAX's compile log by benchmarks/dagger_host_work.py, which measures the same on a GPU."""
    from benchmarks.dagger_host_work import ring

    rows = ring(envs=64, samples=5000, iterations=4)
    assert len({r["samples"] for r in rows}) == 4  # four counts of samples, four shapes before
    assert [r["compiled"] for r in rows][1:] == [0, 0, 0], rows  # nothing compiled after iteration 0


def test_the_resume_checkpoint_writes_the_ring_beside_it_and_restores_it_to_the_bit(tmp_path):
    """`checkpoint` writes the ring's float32 bytes to a file of its own, named by the msgpack (the GIL let go while
    they go out), keeps only the newest such file, and `restore` gives back the same ring, network and optimiser;
    a ring cut short is one line, and a checkpoint from before (the ring inside the msgpack) still restores."""
    import jax
    from flax import serialization

    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.resume import TrainError, checkpoint, restore

    rng = np.random.default_rng(3)
    cfg = DaggerConfig(hidden=(8,), max_samples=300, fit_steps=5, batch=16)
    learner = Learner(cfg)
    for i, n in enumerate([100, 90, 250]):
        learner.add(*_rows(rng, n, cfg.sample_width, 1000 * i), keep=i == 0)
    learner.fit(0)
    path = tmp_path / "resume.msgpack"
    for iteration in (3, 4):
        checkpoint(path, cfg, learner, iteration, 12345, [{"wall_seconds": 1.5}]).join()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["resume-ring-000004.f32", "resume.msgpack"]

    def same(a, b):
        return all(np.array_equal(np.asarray(u), np.asarray(v)) for u, v in zip(jax.tree.leaves(a), jax.tree.leaves(b)))

    back = Learner(cfg)
    assert restore(path, cfg, back) == (5, 12345, [{"wall_seconds": 1.5}], 1.5)
    assert (back.filled, back.head, back.floor) == (learner.filled, learner.head, learner.floor)
    assert same((back.x, back.y, back.params, back.opt_state, back.norm),
                (learner.x, learner.y, learner.params, learner.opt_state, learner.norm))

    tree = serialization.msgpack_restore(path.read_bytes())  # as written before the ring had a file of its own
    for key in ("ring", "ring_shapes"):
        tree.pop(key)
    tree["x"], tree["y"] = np.asarray(learner.x[:learner.filled]), np.asarray(learner.y[:learner.filled])
    old = tmp_path / "old" / "resume.msgpack"
    old.parent.mkdir()
    old.write_bytes(serialization.msgpack_serialize(tree))
    back = Learner(cfg)
    restore(old, cfg, back)
    assert same((back.x, back.y), (learner.x, learner.y))

    ring = tmp_path / "resume-ring-000004.f32"
    ring.write_bytes(ring.read_bytes()[:-4])
    with pytest.raises(TrainError, match="holds .* numbers, its checkpoint names"):
        restore(path, cfg, Learner(cfg))
    ring.unlink()
    with pytest.raises(TrainError, match="unreadable"):
        restore(path, cfg, Learner(cfg))
