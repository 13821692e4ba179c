"""Training on several devices: `train --devices N` splits each rollout's seeds and each minibatch over N
devices, and the result is the one device's, to float tolerance: the same minibatch, its mean gradient averaged
across devices, one set of weights; each seed's episode the same whichever device ran it.

JAX cannot change its device count once imported: the 2-device runs are processes of their own, on 2 CPU devices
forced by XLA_FLAGS (tests/forced_devices.py)."""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from jax.tree_util import tree_leaves as jax_leaves
from helpers import ENV, over

from mjx_pusht.cli.commands import main
from mjx_pusht.train.policy import load_checkpoint
from mjx_pusht.train.devices import check_divides
from mjx_pusht.train.resume import TrainError

pytest.importorskip("flax")
pytest.importorskip("optax")

TWO = {**ENV, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"}


def _forced(what: str) -> dict:
    r = subprocess.run([sys.executable, str(Path(__file__).with_name("forced_devices.py")), what], capture_output=True,
                       text=True, env={**TWO, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_a_fit_and_a_rollout_on_two_devices_are_those_on_one():
    """~30 s: one fit compiled twice, an MJX-Warp rollout compiled three times (8 worlds; 4 on each device); then a
    pixel student's rollout and fit (~40 s), its images drawn on each device by the raster renderer."""
    out = _forced("all:mjx-warp")
    one, two = out["fit"]["1"], out["fit"]["2"]
    assert one["devices"] == 1 and two["devices"] == 2  # the weights held on both devices, one set
    # the minibatch's mean gradient, each device's share averaged: the loss and every weight as on one device
    assert two["loss"] == pytest.approx(one["loss"], rel=1e-6)
    for a, b in zip(one["params"], two["params"], strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-6)
    assert max(np.max(np.abs(np.subtract(a, b))) for a, b in zip(one["params"], out["fit"]["start"])) > 1e-3  # fitted
    one, two = out["rollout"]["1"], out["rollout"]["2"]
    assert two["devices"] == 2  # the samples' rows come from both devices, in seed order
    for k in ("success", "coverage", "finite", "y", "x"):  # every seed's episode and every sample, to the bit
        assert two[k] == one[k], k
    assert len(set(one["coverage"])) == 8  # eight different episodes, not one repeated
    one, two = out["pixels"]["1"], out["pixels"]["2"]
    # the CNN's forward pass on 2 worlds a device is not bitwise the one on 4 (XLA's kernels for other shapes): the
    # students' actions, so the states, agree to float32 rounding, and every episode ends alike
    assert two["coverage"] == one["coverage"]
    np.testing.assert_allclose(two["x"], one["x"], rtol=0, atol=1e-5)
    assert two["loss"] == pytest.approx(one["loss"], rel=1e-5) and two["pose_error_mm"] == pytest.approx(
        one["pose_error_mm"], rel=1e-5)  # each device rendered its share of the minibatches: the same images
    for a, b in zip(one["params"], two["params"], strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)


def test_bad_devices_are_one_line_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "run"
    for argv, needle in ((["--devices", "0"], "must be an integer >= 1"),
                         (["--backend", "mjx-jax", "--devices", "64"], "--devices 64: this process has 1"),
                         (["--backend", "cpu", "--devices", "1"], "the cpu backend steps MuJoCo C"),
                         (["--backend", "mjx-warp", "--algo", "ppo", "--devices", "2"],
                          "--devices 2: this process has 1"),
                         # before joining: nobody listens at port 1, so a join would wait out --peer-timeout
                         (["--num-processes", "2", "--coordinator", "127.0.0.1:1", "--backend", "cpu"],
                          "--num-processes spreads training over the devices of the mjx-jax or mjx-warp backends"),
                         (["--num-processes", "2", "--coordinator", "127.0.0.1:1", "--resume"],
                          "--resume: not with --num-processes yet"),
                         # PPO's stop is raised from Brax's callbacks, which run on process 0 alone
                         (["--num-processes", "2", "--coordinator", "127.0.0.1:1", "--algo", "ppo", "--minutes", "3"],
                          "--minutes: not with --algo ppo over --num-processes"),
                         (["--num-processes", "2", "--coordinator", "127.0.0.1:1", "--algo", "ppo", "--until", "0.9"],
                          "--until: not with --algo ppo over --num-processes")):
        assert main(["train", "--no-rerun", "--out", str(out), *argv]) in (1, 2)
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1, err
    assert not out.exists()


def test_what_does_not_split_evenly_over_the_devices_is_one_line():
    two = [object(), object()]  # the check reads only how many there are
    check_divides(two, envs=8, eval_envs=4, batch=64)
    for sizes, needle in (({"envs": 7}, "--envs (7) must be a multiple of the 2 devices"),
                          ({"image_batch": 5}, "--image-batch (5) must be")):
        with pytest.raises(TrainError, match=re.escape(needle)):
            check_divides(two, **sizes)


def test_ppo_hands_the_device_count_to_braxs_own_device_mapping(tmp_path, monkeypatch):
    """Brax's `ppo.train` maps its rollouts and update over `max_devices_per_host` local devices itself (pmap, its
    gradients pmean'd): `--devices` reaches it there (None: every one). A 2-device run of Brax's trainer on 2 forced
    CPU devices took 7.5 minutes on the 2-core CI machine, so it is not run here (notebook h-devices)."""
    pytest.importorskip("brax")
    from helpers import SMALL_PPO, brax_ppo_arguments

    from mjx_pusht.train.ppo import PPOConfig

    cfg = PPOConfig(**SMALL_PPO)
    given = brax_ppo_arguments(monkeypatch, tmp_path, [(cfg, {"devices": None}), (cfg, {"devices": 2})])
    assert [g["max_devices_per_host"] for g in given] == [None, 2]


TINY = ["train", "--backend", "mjx-warp", "--reset", "chapter", "--envs", "4", "--iterations", "2", "--fit-steps", "20",
        "--batch", "64", "--hidden", "32,32", "--eval-envs", "2", "--max-samples", "5000", "--max-steps", "10",
        "--no-rerun", "--record", "0", "--no-progress"]


@pytest.mark.parametrize("algo", ["dagger", "ppo"])
def test_process_0_refusing_the_folder_ends_every_training_process_in_one_line(tmp_path, algo):
    """Process 0 claims --out for the run; refused there (a user's file in it), process 1 would have trained on and
    waited for process 0 in its first all-reduce for ever (notebook lead29). Both end in one line, before training."""
    if algo == "ppo":
        pytest.importorskip("brax")
    (tmp_path / "notes.txt").write_text("mine")
    port = _free_port()
    tiny = (over(TINY, "--backend", "mjx-jax") if algo == "dagger" else  # PPO's tiny run (its test below)
            ["train", "--algo", "ppo", "--backend", "mjx-jax", "--envs", "8", "--batch", "8", "--timesteps", "10240",
             "--iterations", "1", "--eval-envs", "8", "--hidden", "32,32", "--no-rerun", "--record", "0"])
    args = [*tiny, "--out", str(tmp_path), "--num-processes", "2", "--coordinator", f"127.0.0.1:{port}"]
    procs = [subprocess.Popen([sys.executable, "-m", "mjx_pusht", *args, "--process-id", str(i)],
                              env={**ENV, "JAX_PLATFORMS": "cpu"}, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for i in (1, 0)]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [1, 1], errs
    one, zero = (e.strip().splitlines() for e in errs)
    assert len(zero) == 1 and "holds files train did not write (notes.txt)" in zero[0], zero
    assert len(one) == 1 and "process 0 stopped before any work" in one[0], one
    assert sorted(os.listdir(tmp_path)) == ["notes.txt"]


def test_a_folder_flag_given_to_one_training_process_alone_stops_both(tmp_path):
    """Process 0 alone claims, records and judges, so `--replace` given to it alone (or `--no-rerun` to another) was
    never compared between the processes (the fifteenth pass): both are refused in one line, before any training."""
    port = _free_port()
    args = [*over(TINY, "--backend", "mjx-jax"), "--out", str(tmp_path / "run"), "--num-processes", "2",
            "--coordinator", f"127.0.0.1:{port}"]
    procs = [subprocess.Popen([sys.executable, "-m", "mjx_pusht", *args, "--process-id", str(i), *extra],
                              env={**ENV, "JAX_PLATFORMS": "cpu"}, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for i, extra in ((1, []), (0, ["--replace"]))]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [1, 1], errs
    for err in errs:
        assert len(err.strip().splitlines()) == 1 and "other settings" in err and "replace" in err, err
    assert not (tmp_path / "run").exists()


@pytest.mark.slow
def test_two_processes_joined_by_jax_distributed_train_the_policy_two_devices_of_one_process_do(tmp_path):
    """Two processes on localhost (one CPU device each, their gradients averaged across processes through gloo)
    against one process with 2 forced CPU devices: the same run, so the same weights; process 0 wrote the run."""
    port = _free_port()
    # a compilation cache of its own for each process: in one full-suite run (a cold cache shared with the other
    # tests' processes) the one-process run failed in jax with "safe_zip() argument 1 has length 2 but argument 0
    # has length 4", which it never did alone, cold or warm (notebook lead13); the run takes as long either way
    env = {**ENV, "JAX_PLATFORMS": "cpu"}
    # --minutes: every process stops where process 0's clock says (never here: ten minutes)
    flags = ["--out", str(tmp_path / "two"), "--minutes", "10", "--num-processes", "2", "--coordinator",
             f"127.0.0.1:{port}"]
    # each process dumps the HLO it compiles: a program the two run together must be the same text in both (texts
    # that differed hung Brax's PPO over processes in its GPU compile, notebook lead23)
    procs = [subprocess.Popen([sys.executable, "-m", "mjx_pusht", *TINY, *flags, "--process-id", str(i)],
                              env=_dumping_hlo(env, tmp_path, i),
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for i in (1, 0)]
    one = subprocess.Popen([sys.executable, "-m", "mjx_pusht", *TINY, "--out", str(tmp_path / "one")],
                           env={**TWO, "MJX_PUSHT_JAX_CACHE": str(tmp_path / "cache-one")},
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    logs = [p.communicate(timeout=600)[0] for p in (*procs, one)]
    assert [p.returncode for p in (*procs, one)] == [0, 0, 0], logs
    assert "process 1: trained on 1 of the run's 2 devices; process 0 writes the run" in logs[0]
    runs = [json.loads((tmp_path / d / "summary.json").read_text()) for d in ("two", "one")]
    assert runs[0]["devices"] == runs[1]["devices"] == 2
    assert [r["samples"] for r in runs[0]["curve"]] == [r["samples"] for r in runs[1]["curve"]]
    two, one = (load_checkpoint(tmp_path / d / "policy.msgpack")[0] for d in ("two", "one"))
    for a, b in zip(jax_leaves(two), jax_leaves(one), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)
    assert runs[0]["eval"]["n_episodes"] == 2  # process 0 judged it with eval, as one process does
    together = [_programs_over_processes(tmp_path / f"hlo-{i}") for i in (0, 1)]
    assert together[0] and together[0] == together[1]  # the fit's programs, the same text in both processes


def _dumping_hlo(env: dict, tmp_path: Path, i: int) -> dict:
    """Process i's environment, dumping the HLO it compiles into tmp_path/hlo-i, with a compilation cache of its own
    (a cache hit compiles, and so dumps, nothing)."""
    return {**env, "XLA_FLAGS": f"--xla_dump_to={tmp_path / f'hlo-{i}'} --xla_dump_hlo_as_text",
            "MJX_PUSHT_JAX_CACHE": str(tmp_path / f"cache-{i}")}


def _programs_over_processes(dump: Path) -> list[str]:
    """The texts of the programs, as JAX handed them to XLA, that span both processes' devices, in compile order."""
    texts = [f.read_text() for f in sorted(dump.glob("module_*.before_optimizations.txt"))]
    return [t for t in texts if re.search(r"(replica_count|num_partitions)=2\b", t.partition("\n")[0])]


@pytest.mark.slow
@pytest.mark.skipif(os.environ.get("MJX_PUSHT_HEAVY_TESTS") != "1",
                    reason="3.6 CPU-minutes (MJX-Warp's twice that), more than CI's 30 minutes hold "
                           "(MJX_PUSHT_HEAVY_TESTS=1 runs it)")
@pytest.mark.parametrize("backend", ["mjx-jax", "mjx-warp"])
def test_ppo_over_two_processes_joined_by_jax_distributed_is_one_run_process_0_writes(tmp_path, backend):
    """Brax's own PPO over two processes on localhost (one CPU device each, ~2.5 minutes here on MJX-JAX, ~5 on
    MJX-Warp: each process compiles Brax's epoch; in CI's suite, beside its other worker and LeRobot's tests, it
    pushed the fresh-clone rehearsal to 2,072 s and starved two timed tests, so it runs by hand, notebook lead20):
    Brax maps its epochs over both (its gradients all-reduced through gloo), so both end with the same weights, which
    process 0 judged, wrote and evaluated; process 1 says the digest of the weights it ended with. Two processes that
    trained apart (different envs, keys fold_in(process)) would end with different ones. Brax's epoch is the same
    HLO text in both processes (on MJX-Warp too, whose FFI calls are numbered in the order a process registers
    them)."""
    pytest.importorskip("brax")
    port = _free_port()
    out = tmp_path / "two"
    args = ["train", "--algo", "ppo", "--task", "gym-pusht", "--backend", backend, "--envs", "8", "--batch", "8",
            "--timesteps", "10240", "--iterations", "1", "--eval-envs", "8", "--hidden", "32,32", "--max-steps", "50",
            "--keep", "last", "--no-rerun", "--record", "0", "--no-progress", "--out", str(out), "--num-processes", "2",
            "--coordinator", f"127.0.0.1:{port}"]
    (tmp_path / "tmp").mkdir()  # where process 1 keeps its files while it trains (TMPDIR)
    env = {**ENV, "JAX_PLATFORMS": "cpu", "TMPDIR": str(tmp_path / "tmp")}
    procs = [subprocess.Popen([sys.executable, "-m", "mjx_pusht", *args, "--process-id", str(i)],
                              env=_dumping_hlo(env, tmp_path, i),
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for i in (1, 0)]
    logs = [p.communicate(timeout=600)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], logs
    said = re.search(r"process 1: trained on 1 of the run's 2 devices \(its final weights' digest ([0-9a-f]{16})", logs[0])
    assert said, logs[0]
    assert not any(p.name.startswith("mjx-pusht-train-process-") for p in (tmp_path / "tmp").iterdir())  # removed
    summary = json.loads((out / "summary.json").read_text())
    assert summary["devices"] == 2 and summary["method"] == "ppo"
    assert [r["env_steps"] for r in summary["curve"]] == [0, 10240]  # Brax's steps over both processes' envs
    assert summary["eval"]["n_episodes"] == 8  # process 0 judged the policy with eval, as one process does
    import hashlib

    final = load_checkpoint(out / "policy.msgpack")[0]
    mine = hashlib.sha256(b"".join(np.asarray(a, np.float32).tobytes() for a in jax_leaves(final))).hexdigest()[:16]
    assert said.group(1) == mine  # process 1 ended on the weights process 0 wrote: one run's
    untrained = load_checkpoint(out / "checkpoints" / "policy_000.msgpack")[0]
    assert max(np.max(np.abs(np.subtract(a, b))) for a, b in zip(jax_leaves(final), jax_leaves(untrained))) > 1e-4
    together = [_programs_over_processes(tmp_path / f"hlo-{i}") for i in (0, 1)]
    assert together[0] and together[0] == together[1]  # Brax's epoch, the same text in both processes


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_ppo_over_several_gpus_on_mjx_warp_is_refused_in_the_graph_modes_that_share_a_graph_or_failed(
        tmp_path, capsys, monkeypatch):
    """Refused where MJX_PUSHT_ENV_GRAPH_MODE names a staged mode, whose one captured graph per call site every device
    would replay (the env's default WARP_STAGED failed so on 2 H200s, notebook lead13), or XLA capturing (JAX, failed,
    lead15), naming the way out; unset (a graph per device, WARP, trained on 2 and 4 H200s, lead19), WARP and NONE go
    on to the next check (here: this CPU process has one device)."""
    argv = ["train", "--no-rerun", "--out", str(tmp_path / "run"), "--backend", "mjx-warp", "--algo", "ppo",
            "--devices", "2"]
    for mode, needle in (("WARP_STAGED", "MJX_PUSHT_ENV_GRAPH_MODE=WARP_STAGED fails"),
                         ("WARP_STAGED_EX", "--backend mjx-jax"), ("JAX", "unset it"),
                         (None, "--devices 2: this process has 1"), ("WARP", "--devices 2: this process has 1"),
                         ("NONE", "--devices 2: this process has 1")):
        if mode is None:
            monkeypatch.delenv("MJX_PUSHT_ENV_GRAPH_MODE", raising=False)
        else:
            monkeypatch.setenv("MJX_PUSHT_ENV_GRAPH_MODE", mode)
        assert main(argv) in (1, 2)
        err = capsys.readouterr().err
        assert needle in err and err.count("\n") == 1, err
    assert not (tmp_path / "run").exists()


def test_brax_trains_on_several_gpus_of_mjx_warp_with_a_graph_per_device_unless_told_otherwise(monkeypatch):
    """PPO's env on several MJX-Warp GPUs: WARP (graphs keyed on the device); on one, or on MJX-JAX, or with no GPU
    to capture on, the env's own default; a mode the user names is theirs (the CLI refused those that failed)."""
    from mjx_pusht.train import ppo

    monkeypatch.delenv("MJX_PUSHT_ENV_GRAPH_MODE", raising=False)
    monkeypatch.setattr("mjx_pusht.backends.base.has_gpu", lambda: True)
    assert ppo.graph_mode("mjx-warp", 4) == "WARP" and ppo.graph_mode("mjx-warp", 2) == "WARP"
    assert ppo.graph_mode("mjx-warp", 1) is None and ppo.graph_mode("mjx-jax", 4) is None
    monkeypatch.setenv("MJX_PUSHT_ENV_GRAPH_MODE", "NONE")
    assert ppo.graph_mode("mjx-warp", 4) is None  # the env reads the variable itself
    monkeypatch.delenv("MJX_PUSHT_ENV_GRAPH_MODE")
    monkeypatch.setattr("mjx_pusht.backends.base.has_gpu", lambda: False)
    assert ppo.graph_mode("mjx-warp", 4) is None  # Warp captures graphs on CUDA only


def test_a_rollout_over_the_devices_runs_with_pythons_collector_paused_and_restores_it():
    """Spread.each runs each device's block with the cycle collector off (a finalizer run mid-capture breaks Warp's
    CUDA-graph capture), on one device as on several threads, and puts it back as it was, an error included."""
    import gc

    from mjx_pusht.train.devices import Spread

    seen = []
    assert Spread.each(lambda i: seen.append((i, gc.isenabled())) or i, [(0,), (1,), (2,)]) == [0, 1, 2]
    assert Spread.each(lambda i: seen.append((i, gc.isenabled())) or i, [(3,)]) == [3]
    assert sorted(seen) == [(0, False), (1, False), (2, False), (3, False)] and gc.isenabled()

    def boom(i):
        raise RuntimeError("device lost")

    with pytest.raises(RuntimeError, match="device lost"):
        Spread.each(boom, [(0,), (1,)])
    assert gc.isenabled()
    gc.disable()
    try:  # a caller that had it off keeps it off
        Spread.each(lambda i: i, [(0,)])
        assert not gc.isenabled()
    finally:
        gc.enable()
