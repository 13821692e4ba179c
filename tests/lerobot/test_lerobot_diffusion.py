"""LeRobot's own Diffusion Policy as benchmarks/diffusion_pusht.sh trains and scores it, shrunk to a CPU:
`lerobot-train --policy.type=diffusion` on `mjx-pusht demos`, evaluating on `--env.type=mjx_pusht` as it trains (the
curve's points, read back by benchmarks/diffusion_curve.py), then `lerobot-eval` of its checkpoint on gym-pusht
itself and on the plugin's env."""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import EPISODE, lerobot_eval, run
from safetensors.torch import load_file

STEPS = 2
# the recipe's policy (LeRobot's pusht settings: 2 observations, actions predicted 16 and run 8 at a time, no
# pretrained backbone) made small enough for CI: a narrow UNet, 4 diffusion steps, 32 x 32 images for the ResNet
TINY = ("--policy.type=diffusion", "--policy.device=cpu", "--policy.push_to_hub=false", "--policy.use_amp=false",
        "--policy.pretrained_backbone_weights=null", "--policy.use_group_norm=true", "--policy.down_dims=[16,32]",
        "--policy.horizon=8", "--policy.n_action_steps=4", "--policy.drop_n_last_frames=3",
        "--policy.num_train_timesteps=4", "--policy.diffusion_step_embed_dim=16",
        "--policy.spatial_softmax_num_keypoints=8", "--policy.resize_shape=[32,32]")
ROOT = Path(__file__).resolve().parents[2]  # for benchmarks/
SMALL = ("--env.type=mjx_pusht", "--env.observation_height=96", "--env.observation_width=96")


@pytest.fixture(scope="module")
def trained(demos, tmp_path_factory):
    """lerobot-train's output folder and its log: STEPS updates, a checkpoint, and one eval of two episodes on the
    plugin's env (LeRobot's --env_eval_freq) at the end."""
    out = tmp_path_factory.mktemp("diffusion") / "train"
    p = run("lerobot-train", "--dataset.repo_id=local/mjx_pusht_demos", f"--dataset.root={demos}", *TINY,
            f"--steps={STEPS}", "--batch_size=2", "--num_workers=0", f"--save_freq={STEPS}", "--log_freq=1",
            f"--output_dir={out}", "--wandb.enable=false", *SMALL, f"--env.episode_length={EPISODE}",
            f"--env_eval_freq={STEPS}", "--eval.n_episodes=2", "--eval.batch_size=2", "--eval.use_async_envs=false",
            cwd=out.parent)
    log = out.parent / "train.log"
    log.write_text(p.stdout + p.stderr)
    return out, log


@pytest.mark.slow
def test_lerobot_train_writes_a_diffusion_checkpoint_of_the_demos_features_and_units(trained, demos):
    out, log = trained
    losses = [float(x) for x in re.findall(r"step:\d+ .*? loss:([0-9.eE+-]+)", log.read_text())]
    assert len(losses) == STEPS and all(np.isfinite(losses))  # --log_freq=1: a line an update
    ckpt = out / f"checkpoints/{STEPS:06d}"
    assert json.loads((ckpt / "training_state/training_step.json").read_text())["step"] == STEPS
    assert json.loads((ckpt / "pretrained_model/train_config.json").read_text())["dataset"]["root"] == str(demos)
    assert (ckpt / "pretrained_model/model.safetensors").stat().st_size > 0
    assert (out / "checkpoints/last").resolve() == ckpt.resolve()
    config = json.loads((ckpt / "pretrained_model/config.json").read_text())
    assert config["type"] == "diffusion"
    features = json.loads((demos / "meta/info.json").read_text())["features"]
    h, w, c = features["observation.image"]["shape"]
    state = features["observation.state"]["shape"]
    assert config["input_features"] == {"observation.image": {"type": "VISUAL", "shape": [c, h, w]},
                                        "observation.state": {"type": "STATE", "shape": state}}
    assert config["output_features"] == {"action": {"type": "ACTION", "shape": features["action"]["shape"]}}
    # the policy's action normalisation is the demos' own, in gym-pusht's units (pixels of the 512-pixel frame)
    stats = json.loads((demos / "meta/stats.json").read_text())
    (norm,) = (ckpt / "pretrained_model").glob("policy_preprocessor_step_*_normalizer_processor.safetensors")
    saved = load_file(norm)
    for key in ("action", "observation.state"):
        for stat in ("min", "max"):
            np.testing.assert_allclose(saved[f"{key}.{stat}"].numpy(), stats[key][stat], rtol=1e-6)
    assert 0 <= min(stats["action"]["min"]) and max(stats["action"]["max"]) <= 512


@pytest.mark.slow
def test_the_curve_reads_the_evals_lerobot_train_logs(trained):
    sys.path.insert(0, str(ROOT))
    from benchmarks.diffusion_curve import parse_run

    _, log = trained
    text = log.read_text()
    (point,) = parse_run([log])["points"]
    # against the per-episode line LeRobot logs beside the aggregate the curve reads
    per_task = ast.literal_eval(re.search(r"Suite per_task aggregated: (\[.*\])\s*$", text, re.M)[1])
    successes = [s for task in per_task for s in task["metrics"]["successes"]]
    assert point["step"] == STEPS and point["n_episodes"] == len(successes) == 2
    assert point["successes"] == sum(successes)
    assert 0 <= point["wilson95"][0] <= point["pc_success"] <= point["wilson95"][1] <= 100
    assert 0 <= point["train_min"] < point["wall_min"]  # the eval's own seconds are left out
    assert np.isfinite(point["avg_sum_reward"])


@pytest.mark.slow
def test_lerobot_eval_scores_the_checkpoint_on_gym_pusht_and_on_the_plugins_env(trained, tmp_path):
    policy = trained[0] / "checkpoints/last/pretrained_model"
    # lerobot 0.6.1's default AsyncVectorEnv cannot make gym_pusht/PushT-v0 in its workers: sync, as users must
    gym = lerobot_eval(policy, tmp_path / "pusht", "--env.type=pusht", "--eval.use_async_envs=false")
    # the plugin's env sync too (AsyncVectorEnv's workers cost ~10 s to start on two cores)
    ours = lerobot_eval(policy, tmp_path / "mjx", *SMALL, "--eval.use_async_envs=false")
    assert list(gym["per_group"]) == ["pusht"] and list(ours["per_group"]) == ["mjx_pusht"]
    assert gym["overall"]["n_episodes"] == ours["overall"]["n_episodes"] == 2


@pytest.mark.slow
def test_the_recipe_carries_a_run_across_holds_and_lerobot_resumes_it_from_the_carried_checkpoint(tmp_path):
    """benchmarks/diffusion_pusht.sh on this CPU, as a run across two machine holds goes: the first hold makes the
    demos and trains, its last checkpoint at step 2 of 4 when it ends; `pack-2` cuts the checkpoint and logs into
    parts, `send` returns at most 4 a call; a part missing on the new machine stops `unpack-2` in one line with
    nothing unpacked; with every part, the new hold's `unpack-2 train-2` puts the checkpoint back byte for byte and
    LeRobot's own --resume goes on from it to step 4. (LeRobot 0.6.1's resume is not bit-exact: its data order
    is, but restarting the loader draws once more from the restored torch RNG; a run from scratch is.) Where only
    the policy comes back (`PACK=model`), a later run starts FROM its weights."""
    env = {**os.environ, "PY": sys.executable, "DEVICE": "cpu", "SIZES": "2", "STEPS": "4", "SAVE_FREQ": "2",
           "EVAL_FREQ": "100", "DOWN_DIMS": "16,32", "BATCH": "2", "WORKERS": "0", "WAIT_MIN": "5",
           "CARRIED": str(tmp_path / "carried"), "MJX_PUSHT_JAX_CACHE": str(tmp_path / "cache")}

    def stages(runs, *names, ok=True):
        p = subprocess.run(["bash", "benchmarks/diffusion_pusht.sh", *names], cwd=ROOT, capture_output=True,
                           text=True, timeout=600, env={**env, "RUNS": str(runs), "OUT": str(tmp_path / "out")})
        assert (p.returncode == 0) == ok, p.stdout[-3000:] + p.stderr[-3000:]
        return p.stdout if ok else p.stderr

    runs = tmp_path / "runs"  # the same path on every machine ($HOME/diffusion): the checkpoint names it
    env["STOP_AT"] = "2"  # the hold ends between the two checkpoints: the schedule is 4 updates long, the run 2
    stages(runs, "demos-2", "train-2", "wait")
    del env["STOP_AT"]
    ckpts = runs / "train-2" / "checkpoints"
    assert sorted(c.name for c in ckpts.iterdir()) == ["000002", "last"]
    assert (ckpts / "last").readlink() == Path("000002")
    first_log = next((runs / "logs").glob("train-2-*.log")).read_text()
    assert "STOP_AT: the step-2 checkpoint is saved; stopping the run" in first_log
    assert json.loads((ckpts / "000002/pretrained_model/train_config.json").read_text())["steps"] == 4
    assert stages(runs, "pack-3", ok=False).strip() == f"pack-3: {runs}/train-3 has no checkpoint to pack"
    stages(runs, "pack-2")
    parts = sorted((runs / "pack").glob("train-2.tar.part.*"))
    carried = tmp_path / "carried"
    carried.mkdir()
    for _ in range(len(parts) // 4 + 1):  # a call each, as the device's 8 files a call allow
        shutil.rmtree(tmp_path / "out", ignore_errors=True)
        stages(runs, "send")
        sent = sorted((tmp_path / "out" / "parts").glob("*.part.*"))
        assert 0 < len(sent) <= 4
        for f in (tmp_path / "out" / "parts").iterdir():
            shutil.copy(f, carried)
    assert "every part was sent already" in stages(runs, "send")
    first = runs.rename(tmp_path / "hold1")  # the first machine, gone
    assert sorted(p.name for p in carried.glob("*.part.*")) == [p.name for p in parts]
    last = carried / parts[-1].name
    last.rename(tmp_path / "held-back")
    assert stages(runs, "unpack-2", ok=False).strip().splitlines() == [  # one line, on stderr
        f"unpack-2: parts missing or damaged in {carried} (sha256sum -c train-2.sha256 there names them)"]
    assert not (runs / "train-2").exists()
    (tmp_path / "held-back").rename(last)
    stages(runs, "demos-2", "unpack-2")
    env["STOP_AT"] = "2"  # a resumed run starts after step 2: it would never write that checkpoint again
    assert stages(runs, "train-2", ok=False).strip().splitlines() == [
        "STOP_AT 2 is not ahead of the checkpoint train-2 resumes from (step 2)"]
    del env["STOP_AT"]
    stages(runs, "train-2", "wait")
    model = "checkpoints/000002/pretrained_model/model.safetensors"
    assert (runs / "train-2" / model).read_bytes() == (first / "train-2" / model).read_bytes()
    state = runs / "train-2/checkpoints/000004/training_state/training_step.json"
    assert json.loads(state.read_text())["step"] == 4
    resumed = max((runs / "logs").glob("train-2-*.log"), key=lambda p: p.stat().st_mtime).read_text()
    assert "'resume': True" in resumed and "Resuming data order at epoch 0, sample 4" in resumed
    assert "End of training" in resumed

    # where only the policy came back (PACK=model: its weights, config and normalizers, not the optimizer), a run
    # in a third hold starts FROM it with LeRobot's --policy.path: at a learning rate of ~0 its one update leaves
    # those weights as they were (a policy made afresh would differ from them by Adam's first steps, ~1e-4)
    env["PACK"] = "model"
    stages(first, "pack-2")
    packed, listing = _packed(first, 2)
    assert {n for n in listing if not n.endswith("/")} == {
        f"train-2/checkpoints/000002/pretrained_model/{f.name}"
        for f in (first / "train-2/checkpoints/000002/pretrained_model").iterdir()}
    third = tmp_path / "hold3"
    third.mkdir()
    subprocess.run(["tar", "xf", "-", "-C", str(third)], input=packed, check=True)
    shutil.copytree(runs / "demos-2", third / "demos-2")
    policy = third / "train-2/checkpoints/000002/pretrained_model"
    policy.rename(third / "policy")
    shutil.rmtree(third / "train-2")
    env.update(FROM=str(third / "policy"), LR="1e-12", STEPS="1", SAVE_FREQ="1")
    stages(third, "train-2", "wait")
    ckpt = third / "train-2/checkpoints/000001/pretrained_model"
    assert json.loads((ckpt / "train_config.json").read_text())["policy"]["pretrained_path"] == str(third / "policy")
    before, after = load_file(third / "policy/model.safetensors"), load_file(ckpt / "model.safetensors")
    assert before.keys() == after.keys()
    assert max(float((after[k].float() - before[k].float()).abs().max()) for k in before) < 1e-8


@pytest.mark.parametrize("pack", ["resume", "live"])
def test_pack_stops_a_training_still_running_before_it_cuts_the_checkpoint_unless_live(tmp_path, pack):
    """A hold ends while lerobot-train still runs (it is detached): `pack-N` stops it first, so no checkpoint is
    written under tar's feet, then packs the last one. PACK=live leaves it running and packs the checkpoint `last`
    named (a finished one: LeRobot moves `last` after writing), so the parts can leave during the hold. The training
    here is a stand-in process group, as `detach` starts it (its own session, the pid file written from inside),
    since what is tested is the script, not LeRobot."""
    runs = tmp_path / "runs"
    ckpt = runs / "train-5" / "checkpoints"
    (ckpt / "000002" / "pretrained_model").mkdir(parents=True)
    (ckpt / "000002" / "pretrained_model" / "model.safetensors").write_bytes(b"weights")
    (ckpt / "last").symlink_to("000002")
    (runs / "logs").mkdir()
    (runs / "pids").mkdir()
    pidfile = runs / "pids" / "train-5"
    # started from a shell that exits at once, as `detach`'s caller does: the stand-in is then no child of this test
    # (a child of ours, unreaped, would stay a zombie that `kill -0` still finds)
    subprocess.run(["bash", "-c", 'setsid bash -c \'echo $$ > "$0"; exec sleep 300\' "$0" &', str(pidfile)], check=True)
    for _ in range(50):
        if pidfile.exists() and pidfile.read_text().strip():
            break
        time.sleep(0.1)
    pid = int(pidfile.read_text())
    p = subprocess.run(["bash", "benchmarks/diffusion_pusht.sh", "pack-5"], cwd=ROOT, capture_output=True, text=True,
                       timeout=60, env={**os.environ, "RUNS": str(runs), "OUT": str(tmp_path / "out"), "PACK": pack})
    assert p.returncode == 0, p.stderr
    if pack == "live":
        assert "stopped" not in p.stdout
        os.kill(pid, 0)  # still training
        os.killpg(pid, signal.SIGTERM)
    else:
        assert "pack-5: stopped the running train-5" in p.stdout
        with pytest.raises(ProcessLookupError):
            os.kill(pid, 0)
    packed, listing = _packed(runs, 5)
    assert "train-5/checkpoints/000002/pretrained_model/model.safetensors" in listing
    # unpacked, `last` names the packed step, as LeRobot's --resume reads it
    subprocess.run(["tar", "xf", "-", "-C", str(tmp_path / "out")], input=packed, check=True)
    assert os.readlink(tmp_path / "out" / "train-5" / "checkpoints" / "last") == "000002"


def _packed(runs, n):
    """`pack-N`'s parts joined again, and the names their tar holds."""
    packed = b"".join(f.read_bytes() for f in sorted((runs / "pack").glob(f"train-{n}.tar.part.*")))
    listing = subprocess.run(["tar", "tf", "-"], input=packed, capture_output=True, check=True).stdout.decode()
    return packed, listing.splitlines()


@pytest.mark.parametrize("var, value, line", [
    ("SCHED", "ddim", "SCHED must be DDPM or DDIM (LeRobot's samplers), got 'ddim'"),
    ("INFER_STEPS", "0", "INFER_STEPS must be a whole number above 0, got '0'"),
    ("BATCH", "abc", "BATCH must be a whole number above 0, got 'abc'"),
    ("STEPS", "rate", "STEPS must be a whole number above 0, got 'rate'"),
    ("LR", "1e-4x", "LR must be a number (e.g. 1e-4), got '1e-4x'"),
    ("EVAL_GPUS", "2,3", 'EVAL_GPUS must be one or two GPU numbers (e.g. "2 3"), got \'2,3\''),
    ("FROM", "nowhere", "FROM must be a pretrained_model folder (with config.json), got 'nowhere'"),
    ("STOP_AT", "0", "STOP_AT must be a whole number above 0, got '0'"),
    ("PACK", "alive", "PACK must be resume, model or live, got 'alive'")])
def test_a_bad_setting_is_one_line_before_anything_starts(tmp_path, var, value, line):
    """A value LeRobot cannot take would otherwise surface minutes later in a detached training's log."""
    p = subprocess.run(["bash", "benchmarks/diffusion_pusht.sh", "train-2"], cwd=ROOT, capture_output=True, text=True,
                       timeout=60, env={**os.environ, var: value, "RUNS": str(tmp_path / "runs"),
                                        "OUT": str(tmp_path / "out")})
    assert (p.returncode, p.stderr.strip().splitlines(), p.stdout) == (2, [line], "")
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("stop_at", ["3", "4"])
def test_a_stop_at_no_checkpoint_before_the_end_is_one_line_before_the_run_starts(tmp_path, stop_at):
    """STOP_AT names a checkpoint the run writes before its schedule's end: any other step would never stop it."""
    env = {**os.environ, "STOP_AT": stop_at, "STEPS": "4", "SAVE_FREQ": "2", "RUNS": str(tmp_path / "runs"),
           "OUT": str(tmp_path / "out")}
    p = subprocess.run(["bash", "benchmarks/diffusion_pusht.sh", "train-2"], cwd=ROOT, capture_output=True, text=True,
                       timeout=60, env=env)
    line = f"STOP_AT must be a checkpoint's step before the run's end (a multiple of SAVE_FREQ 2 below STEPS 4), got {stop_at}"
    assert (p.returncode, p.stderr.strip().splitlines(), p.stdout) == (2, [line], "")
    assert not (tmp_path / "runs/train-2").exists() and not list((tmp_path / "runs/pids").iterdir())


@pytest.mark.parametrize("settings, line", [
    ({"FROM": "x"}, "diffusion-hold: FROM and STOP_AT are for the run on GPU 0 alone; give SMALL=0 with them"),
    ({"SIZE0": "200"}, "diffusion-hold: SIZE0=200 trains the 200 episodes on GPU 0; give SMALL=0 with it"),
    ({"SMALL": "0", "BATCH": "abc"}, "BATCH must be a whole number above 0, got 'abc'")])
def test_the_one_hold_stage_refuses_a_bad_setting_before_any_run_starts(tmp_path, settings, line):
    """gpu.sh diffusion-hold on the lent host: a refused setting is its one line and exit 2, no run folder made."""
    p = subprocess.run(["bash", "benchmarks/gpu.sh", "diffusion-hold", "h200"], cwd=ROOT, capture_output=True, text=True,
                       timeout=60, env={**os.environ, **settings, "HOME": str(tmp_path), "OUT": str(tmp_path / "out")})
    assert (p.returncode, p.stderr.strip().splitlines()) == (2, [line])
    assert not (tmp_path / "diffusion").exists()


@pytest.mark.parametrize("step", ["abc", "0"])
def test_the_stopping_trainer_refuses_a_step_that_is_not_one_in_one_line(step):
    p = subprocess.run([sys.executable, "-m", "benchmarks.lerobot_train_until", step], cwd=ROOT, capture_output=True,
                       text=True, timeout=120)
    assert p.returncode != 0 and p.stdout == "" and len(p.stderr.strip().splitlines()) == 1
    assert "STEP a whole number above 0" in p.stderr and "Traceback" not in p.stderr
