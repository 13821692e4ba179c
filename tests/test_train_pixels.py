"""DAgger from pixels (issue 22): the student sees the env's 96 x 96 image and the pusher's position, and its
checkpoint is a controller that every backend shows the same image to.

One tiny run on MuJoCo C (chapter starts, OpenGL images) is shared by the tests; learning from pixels is
measured on the GPU (NOTES change 21), not here.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from helpers import cli, train_run

pytest.importorskip("flax")
pytest.importorskip("optax")

from mjx_pusht.task.controllers import NEAR, REVERSE, ControllerError, load
from mjx_pusht.train.policy import apply, feature_size, features, load_checkpoint, save

TINY = ("--backend", "cpu", "--reset", "chapter", "--obs", "pixels_agent_pos", "--envs", "4", "--iterations", "2",
        "--fit-steps", "4", "--batch", "16", "--image-batch", "8", "--hidden", "16", "--eval-envs", "4", "--max-samples", "4000",
        "--no-rerun", "--record", "0", "--no-progress")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return train_run(tmp_path_factory, *TINY)


@pytest.fixture(scope="module")
def env():
    from mjx_pusht.envs.functional import PushTEnv

    return PushTEnv(backend="cpu", reset_kind="chapter", pixels=96, keep_states=False)


def test_a_pixel_run_is_judged_alike_by_its_own_rollout_and_by_eval_which_renders_for_the_controller(run):
    summary = json.loads((run / "summary.json").read_text())
    assert summary["obs_type"] == "pixels_agent_pos" and len(summary["curve"]) == 2
    params, meta = load_checkpoint(run / "policy.msgpack")
    assert meta["image"] == 96 and load(f"policy:{run / 'policy.msgpack'}").pixels == 96
    # eval's backend rolls the checkpoint out with its own renderer and its own episode loop, one seed a job: the
    # trainer's rollout of each seed alone is the same episode, to the bit
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.train.dagger import DaggerConfig, Rollouts

    rows = pq.read_table(run / "eval" / "per_episode.parquet").to_pydict()
    assert rows["seed"] == list(range(1_000_000_000, 1_000_000_004))
    cfg = DaggerConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in summary["config"].items()})
    env = PushTEnv(backend="cpu", reset_kind=cfg.reset, pixels=96, keep_states=False)
    rollouts, norm = Rollouts(env, cfg), (np.asarray(meta["in_mean"]), np.asarray(meta["in_std"]))
    alone = [rollouts(params, norm, [seed], 0.0, 99, learn=0)[2] for seed in rows["seed"]]
    assert [float(a["coverage"][0]) for a in alone] == rows["final_coverage"]
    assert [bool(a["success"][0]) for a in alone] == rows["success"]
    # The curve's point rolled the four together: BLAS blocks the convolutions' products by the batch's size,
    # the last bit of an action differs, and an image's edge pixel can flip on it; so close, not equal
    assert summary["curve"][-1]["coverage"] == pytest.approx(np.mean(rows["final_coverage"]), abs=0.01)


def _assert_rendered_again_as_shown(env):
    import jax

    s = env.reset(np.arange(6))
    s = env.step(s, np.tile([[0.4, -0.3]], (6, 1)))
    images = env.images(6)  # kept alive until the images are read: Warp frees a renderer's buffers with it
    again = np.asarray(jax.jit(images)(np.asarray(s.obs["state"], np.float32)))
    shown = np.asarray(s.obs["pixels"])
    # float32 states (what the dataset holds) move an edge pixel at most
    assert (again != shown).any(axis=-1).mean() < 1e-3
    assert len(np.unique(shown.reshape(-1, 3), axis=0)) >= 3  # table, target, block at least: a real image


def test_the_fit_renders_each_sample_as_the_rollout_showed_it(env):
    """The dataset keeps the state an image is a function of, not the image: rendered again, it is the same bytes."""
    _assert_rendered_again_as_shown(env)


@pytest.mark.slow
@pytest.mark.warp
def test_on_mjx_warp_too_the_fit_renders_each_sample_as_the_rollout_showed_it():
    from mjx_pusht.backends.warp import warp_available
    from mjx_pusht.envs.functional import PushTEnv

    if not warp_available():
        pytest.skip("warp-lang is not installed")
    _assert_rendered_again_as_shown(PushTEnv(backend="mjx-warp", reset_kind="chapter", pixels=96, keep_states=False))


def test_a_saved_pixel_policy_acts_as_the_training_process_network_in_numpy_and_in_jax(run, env):
    import jax
    import jax.numpy as jnp

    from mjx_pusht.train.policy import network

    params, meta = load_checkpoint(run / "policy.msgpack")
    s = env.reset(np.arange(8))
    memory = np.array([0, 1, 2, 3, 1 | NEAR, 2 | REVERSE, 3 | NEAR, 0])
    x = features(s.obs, "pixels_agent_pos", memory).astype(np.float32)
    assert x.shape == (8, feature_size("pixels_agent_pos"))
    image = s.obs["pixels"]
    model = network(tuple(meta["config"]["hidden"]), meta["activation"], 96)  # what training applied (flax)
    norm = (np.asarray(meta["in_mean"], np.float32), np.asarray(meta["in_std"], np.float32))
    head, _ = model.apply({"params": jax.tree.map(jnp.asarray, params)}, (x - norm[0]) / norm[1], image, x[:, :2])
    head = np.asarray(head)
    trained = np.tanh(head[:, :2])
    moves = head[:, 2:6].argmax(-1) | np.where(head[:, 6] > 0, NEAR, 0) | np.where(head[:, 7] > 0, REVERSE, 0)
    for action, mem in (apply(params, meta, x.astype(np.float64), image),  # NumPy, on MuJoCo C's side
                        jax.jit(lambda v, im: apply(params, meta, v, im))(jnp.asarray(x), jnp.asarray(image))):
        assert np.abs(np.asarray(action) - trained).max() < 1e-5
        np.testing.assert_array_equal(np.asarray(mem), moves)
    # the image matters: the same features with another start's image act otherwise
    other, _ = apply(params, meta, x.astype(np.float64), image[::-1])
    assert np.abs(other - apply(params, meta, x.astype(np.float64), image)[0]).max() > 1e-6


def test_a_pixel_policy_given_the_true_pose_reads_what_a_state_policy_reads():
    """The pixel policy acts on its pose estimate through the state features' tee terms: with the true pose (the
    estimate it is taught, `pose_target`) they are the state policy's position, yaw and body-frame pusher."""
    from mjx_pusht.train.policy import POSE_SCALE, pose_features, pose_target

    rng = np.random.default_rng(0)
    state = np.column_stack([rng.uniform(-0.35, 0.35, (50, 4)), rng.uniform(-np.pi, np.pi, 50)])
    read = pose_features(pose_target(state), state[:, :2])
    full = features({"state": state}, "state", np.zeros(50, np.int32))  # p, o, cos, sin, body, memory
    np.testing.assert_allclose(read[:, :2] * POSE_SCALE, full[:, 2:4], atol=1e-12)
    np.testing.assert_allclose(read[:, 2:4], full[:, 4:6], atol=1e-12)
    np.testing.assert_allclose(read[:, 4:6] * POSE_SCALE, full[:, 6:8], atol=1e-12)


def test_a_pixel_checkpoint_that_does_not_say_its_image_or_holds_another_trunk_is_one_line(run, tmp_path):
    params, meta = load_checkpoint(run / "policy.msgpack")
    no_image = tmp_path / "no_image.msgpack"
    save(no_image, params, {k: v for k, v in meta.items() if k != "image"})
    other = tmp_path / "trunk.msgpack"
    save(other, {**params, "Conv_1": {"kernel": np.zeros((5, 5, 32, 32)), "bias": np.zeros(32)}}, meta)
    state_with_image = tmp_path / "state.msgpack"
    save(state_with_image, params, {**meta, "obs_type": "state"})
    unread = tmp_path / "no_pose.msgpack"  # change 24's pixel policies: the map straight into the Dense layers
    save(unread, {k: v for k, v in params.items() if not k.startswith("Pose_")}, meta)
    for path, why in ((no_image, "image size"), (other, "Conv_1 is not"), (state_with_image, "image size"),
                      (unread, "Pose_0 is not")):
        with pytest.raises(ControllerError, match=why):
            load(f"policy:{path}")


def test_pixels_where_they_cannot_be_had_are_one_line(run, tmp_path):
    r = cli("train", "--algo", "ppo", "--backend", "mjx-jax", "--obs", "pixels_agent_pos", "--out", str(tmp_path / "p"))
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and "pixels_agent_pos" in r.stderr


@pytest.mark.slow
def test_the_fit_teaches_the_pose_reader_the_pose_each_image_shows(env):
    """A pixel student reads the T's pose from the image and acts on that reading; the fit teaches the reader the
    pose its images show. Judged on fresh images, apart from the fit: the error falls well below what a reader that
    ignores the image can do (the training poses' mean), and the fit's own figure (`pose_error_mm`) agrees."""
    import jax

    from mjx_pusht.train.dagger import DaggerConfig, Learner
    from mjx_pusht.train.policy import POSE_SCALE, pose_target, read_pose

    def states(n, seed):  # pusher and T anywhere a task episode puts them
        r = np.random.default_rng(seed)
        return np.column_stack([r.uniform(-0.36, 0.36, (n, 2)), r.uniform(-0.27, 0.27, (n, 2)),
                                r.uniform(-np.pi, np.pi, n)])

    cfg = DaggerConfig(obs_type="pixels_agent_pos", batch=32, image_batch=16, fit_steps=150, hidden=(16,),
                       max_samples=2048)
    learner = Learner(cfg, env.images(cfg.image_batch))
    train = states(2048, 0)
    rows = np.column_stack([train, train[:, :2], np.zeros((2048, feature_size("pixels_agent_pos") - 2))])
    learner.add(rows, np.zeros((2048, 3)))
    test = states(64, 1)
    images = np.asarray(jax.jit(env.images(64))(test.astype(np.float32)))

    def rms_mm(pose):
        return float(np.sqrt(np.mean((pose - pose_target(test)) ** 2)) * POSE_SCALE * 1000)

    blind = rms_mm(pose_target(train).mean(0))  # ~115 mm
    learner.fit(0)
    read = rms_mm(read_pose(jax.tree.map(np.asarray, learner.params), "relu", images, np.float64))
    assert read < 0.6 * blind, (read, blind)
    assert learner.pose_error_mm == pytest.approx(read, rel=0.5)
