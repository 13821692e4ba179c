"""DAgger from pixels: the student sees the env's 96 x 96 image and the pusher's position, and its
checkpoint is a controller that every backend shows the same image to.

One tiny run on MuJoCo C (chapter starts, OpenGL images) is shared by the tests; learning from pixels is
measured on the GPU (notebook change 21), not here.
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


@pytest.mark.slow  # 42 s: eval renders every step of the held-out episodes on the CPU
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
    # The curve's point rolled the four together, and a row's actions do not depend on the rows beside it, so
    # it is the same episodes too (before, BLAS summed the products in an order it picked by the batch's size,
    # the last bit of an action differed and an image's edge pixel could flip on it)
    assert summary["curve"][-1]["coverage"] == np.mean(rows["final_coverage"])


@pytest.mark.slow  # 2 MJX-JAX programs compiled on the CPU
def test_on_mjx_jax_eval_shows_a_pixel_policy_the_raster_images_training_rolled_it_out_on(run):
    """Where MJX-Warp's renderer cannot serve (MJX-JAX; a program a device), eval's backend draws a pixel
    controller's images with the raster renderer, as DAgger's rollouts do: the same episodes, verdict by verdict."""
    from dataclasses import replace

    from mjx_pusht import Scenario, SceneSpec, make_backend
    from mjx_pusht.envs.functional import PushTEnv
    from mjx_pusht.train.dagger import DaggerConfig, Rollouts

    summary = json.loads((run / "summary.json").read_text())
    cfg = DaggerConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in summary["config"].items()})
    cfg = replace(cfg, max_steps=25)
    params, meta = load_checkpoint(run / "policy.msgpack")
    seeds = np.arange(1_000_000_000, 1_000_000_004)
    rows = make_backend("mjx-jax", Scenario(SceneSpec(), reset=cfg.reset, controller=load(f"policy:{run / 'policy.msgpack'}"),
                                            episode=cfg.episode())).run(seeds)
    env = PushTEnv(backend="mjx-jax", reset_kind=cfg.reset, pixels=96, raster=True, keep_states=False,
                   episode=cfg.episode())
    norm = (np.asarray(meta["in_mean"]), np.asarray(meta["in_std"]))
    trained = Rollouts(env, cfg)(params, norm, seeds, 0.0, 99, learn=0)[2]
    np.testing.assert_allclose(rows.episode["coverage"], trained["coverage"], atol=1e-4)
    assert [bool(x) for x in rows.episode["success"]] == [bool(x) for x in trained["success"]]


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


@pytest.mark.slow  # the `run` fixture, a pixel training run: 38 s of the fast loop (notebook lead13)
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


@pytest.mark.slow  # the `run` fixture, a pixel training run: 38 s of the fast loop (notebook lead13)
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


def test_pixels_where_they_cannot_be_had_are_one_line(tmp_path):
    r = cli("train", "--algo", "ppo", "--backend", "mjx-jax", "--obs", "pixels_agent_pos", "--out", str(tmp_path / "p"))
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and "pixels_agent_pos" in r.stderr


@pytest.mark.slow
def test_the_fit_teaches_the_pose_reader_the_pose_each_image_shows(env):
    """A pixel student reads the T's pose from the image and acts on that reading; the fit teaches the reader the
    pose its images show. Judged on fresh images, apart from the fit: the error falls well below what a reader that
    ignores the image can do (the training poses' mean), and the fit's own figure (`pose_error_mm`) agrees."""
    import jax

    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.learner import Learner
    from mjx_pusht.train.policy import POSE_SCALE, pose_target, read_pose

    def states(n, seed):  # pusher and T anywhere a task episode puts them
        r = np.random.default_rng(seed)
        return np.column_stack([r.uniform(-0.36, 0.36, (n, 2)), r.uniform(-0.27, 0.27, (n, 2)),
                                r.uniform(-np.pi, np.pi, n)])

    # 70 steps: the reader's error 47 mm against the blind 113 (measured 2026-11-26; 150 steps cost the suite 100 s)
    cfg = DaggerConfig(obs_type="pixels_agent_pos", batch=32, image_batch=16, fit_steps=70, hidden=(16,),
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



def _pixel_learner(env, render=None, rows=256, **kw):
    """A small pixel Learner with `rows` ring samples of states anywhere a task episode puts pusher and T."""
    from mjx_pusht.train.dagger import DaggerConfig
    from mjx_pusht.train.learner import Learner

    r = np.random.default_rng(0)
    states = np.column_stack([r.uniform(-0.3, 0.3, (rows, 4)), r.uniform(-np.pi, np.pi, rows)])
    memory = r.integers(0, 4, rows)
    x = np.column_stack([states, features({"state": states}, "pixels_agent_pos", memory)])
    y = np.column_stack([r.uniform(-0.3, 0.3, (rows, 2)), memory])
    cfg = DaggerConfig(obs_type="pixels_agent_pos", batch=16, image_batch=8, hidden=(16,), max_samples=rows, **kw)
    learner = Learner(cfg, render or env.images(cfg.image_batch))
    learner.add(x, y)
    return learner


@pytest.mark.slow  # 15-22 s in the fast loop: two DAgger runs or fits
def test_the_actions_and_the_reader_fitted_apart_are_the_one_scan_fit_they_replace(env):
    """A pixel student's acting layers and image reader share no weights, so the fit runs them as two scans with
    an Adam each (the actions then need not render). With as many steps each, that is exactly the fit change 25
    measured: one scan, one Adam over all weights, both losses every step. That fit, written out here, and the
    Learner's end at the same weights and report the same loss and pose error."""
    import jax
    import jax.numpy as jnp
    import optax

    from mjx_pusht.task.rules import CTRL_LIMIT
    from mjx_pusht.train.dagger import MEMORY_WEIGHT, RENDER_KEY
    from mjx_pusht.train.policy import LATCHES, MOVES, POSE_SCALE, pose_target

    # unclipped: change 25's fit had no clip, and the split fit clips each part's gradient on its own
    learner = _pixel_learner(env, fit_steps=12, max_grad_norm=None)
    cfg, render, k = learner.cfg, env.images(8), 8
    params0, norm = learner.params, tuple(jnp.asarray(a) for a in learner.norm)
    x, y, key = learner.x, learner.y, jax.random.fold_in(jax.random.key(cfg.seed + 1), 0)
    decay = optax.cosine_decay_schedule(cfg.learning_rate, cfg.fit_steps, alpha=0.05)
    opt = optax.adam(lambda count: decay(count % cfg.fit_steps))

    def loss_fn(p, xb, yb, state):  # change 25's: the actions from the true pose, the pose from k images
        xb = (xb - norm[0]) / norm[1]
        truth = pose_target(state)
        head = learner.model.apply({"params": p}, xb, None, state[:, :2], truth)[0]
        mse = jnp.mean(jnp.sum((jnp.tanh(head[:, :2]) * CTRL_LIMIT - yb[:, :2]) ** 2, axis=-1))
        memory = yb[:, 2].astype(jnp.int32)
        move = optax.softmax_cross_entropy_with_integer_labels(head[:, 2:2 + MOVES], memory & (NEAR - 1))
        bits = jnp.stack([(memory & b) != 0 for b in LATCHES], -1).astype(jnp.float32)
        latch = optax.sigmoid_binary_cross_entropy(head[:, 2 + MOVES:], bits).sum(-1)
        _, pose = learner.model.apply({"params": p}, xb[:k], render(state[:k]), state[:k, :2])
        pose_mse = jnp.mean(jnp.sum((pose - truth[:k]) ** 2, axis=-1))
        return mse + MEMORY_WEIGHT * jnp.mean(move + latch) + pose_mse, pose_mse  # change 25's POSE_WEIGHT: 1

    def step(c, key):
        p, o = c
        idx = jax.random.randint(key, (cfg.batch,), 0, learner.filled)
        (loss, pose_mse), g = jax.value_and_grad(loss_fn, has_aux=True)(p, x[idx, RENDER_KEY:], y[idx],
                                                                        x[idx, :RENDER_KEY])
        updates, o = opt.update(g, o, p)
        return (optax.apply_updates(p, updates), o), (loss, pose_mse)

    (joint, _), (losses, poses) = jax.lax.scan(step, (params0, opt.init(params0)), jax.random.split(key, 12))
    loss = learner.fit(0)
    assert learner.params.keys() == joint.keys()
    for name in joint:
        for leaf in ("kernel", "bias"):
            np.testing.assert_allclose(learner.params[name][leaf], joint[name][leaf], rtol=1e-5, atol=1e-6,
                                       err_msg=name)
    assert loss == pytest.approx(float(losses[-1:].mean()), rel=1e-5)  # the last tenth of 12 steps: the last
    assert learner.pose_error_mm == pytest.approx(float(np.sqrt(poses[-1] / 4) * POSE_SCALE * 1000), rel=1e-5)
    moved = {n[:5] for n in joint if not np.allclose(joint[n]["kernel"], params0[n]["kernel"])}
    assert moved == {"Conv_", "Pose_", "Dense"}  # both parts learned: not the agreement of two fits of nothing


@pytest.mark.slow  # 17 s: the fast loop was at 2:58-3:05 (notebook lead13)
def test_only_the_image_steps_render_and_the_actions_fit_does_not_depend_on_them(env):
    """--image-steps: the reader's steps an iteration, apart from the actions' --fit-steps. Only the reader's steps
    render (one render of --image-batch images each), and the acting layers end where they would with any number
    of image steps, while the reader's do not."""
    import jax

    render, calls, fits = env.images(8), [], {}

    def counted(states):  # the renderer, counting the renders the fit runs (not the times it is traced)
        jax.debug.callback(lambda s: calls.append(len(s)), states)
        return render(states)

    for image_steps in (3, 7):
        learner = _pixel_learner(env, counted, fit_steps=20, image_steps=image_steps)
        calls.clear()
        learner.fit(0)
        jax.effects_barrier()
        assert calls == [8] * image_steps
        fits[image_steps] = learner.params
    for name, layer in fits[3].items():  # (close, not equal: two programs, whose fusions XLA may choose apart)
        same = np.allclose(layer["kernel"], fits[7][name]["kernel"], rtol=1e-6, atol=1e-7)
        assert same == name.startswith("Dense_"), name
