"""Sweeps: rows equal single runs, MJX agrees with the CPU reference, sharding, resume, loud failures."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import types

import numpy as np
import pytest
from helpers import assert_matches_cpu

from mjx_pusht.backends.base import Backend
from mjx_pusht.backends.cpu import CpuBackend
from mjx_pusht.backends.results import COLUMNS, Rollouts, scene_metrics
from mjx_pusht.cli.commands import main
from mjx_pusht.io.outputs import read_table
from mjx_pusht.model.scene import SceneSpec
from mjx_pusht.model.tree import read_tree
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.seeds import SeedSpecError, parse_seeds
from mjx_pusht.study.sweep import finish, run_sweep


def test_seed_specs():
    np.testing.assert_array_equal(parse_seeds("4"), [0, 1, 2, 3])
    np.testing.assert_array_equal(parse_seeds("10:13"), [10, 11, 12])
    np.testing.assert_array_equal(parse_seeds("5,1,9"), [5, 1, 9])
    for bad in ("", "abc", "5:2", "3:3", "0", "1:2:3", "1,,2", "-4", "1,1"):
        with pytest.raises(SeedSpecError):
            parse_seeds(bad)


@pytest.mark.parametrize("break_it", ["none", "split-tee"])
def test_cpu_sweep_rows_equal_scene_runs(tmp_path, break_it):
    out = tmp_path / "sweep"
    assert main(["sweep", "--seeds", "8", "--backend", "cpu", "--break", break_it, "--out", str(out),
                 "--no-rerun", "--no-progress", "--chunk", "3"]) == 0
    table = read_table(out / "per_seed.parquet")
    assert list(table) == list(COLUMNS)
    rows = Rollouts.from_columns(table)
    for s in range(8):
        scene_out = tmp_path / f"scene{s}"
        assert main(["scene", "--seed", str(s), "--break", break_it, "--no-rerun", "--out", str(scene_out)]) == 0
        single = json.loads((scene_out / "metrics.json").read_text())
        tree = read_tree(CpuBackend(Scenario(SceneSpec(break_it))).model)
        assert scene_metrics(rows, s, tree, break_it) == single




@pytest.mark.slow
@pytest.mark.parametrize("break_it", ["none", "split-tee"])
def test_mjx_jax_agrees_with_cpu_before_contact_and_on_every_verdict(mjx_jax_runs, cpu_runs, break_it):
    assert_matches_cpu(mjx_jax_runs[break_it], cpu_runs[(break_it, "capsule")])


@pytest.mark.slow
@pytest.mark.warp
@pytest.mark.parametrize("break_it", ["none", "split-tee"])
def test_mjx_warp_agrees_with_cpu_before_contact_and_on_every_verdict(mjx_warp_runs, cpu_runs, break_it):
    assert_matches_cpu(mjx_warp_runs[break_it], cpu_runs[(break_it, "cylinder")])


@pytest.mark.slow
def test_split_tee_is_split_on_every_seed_and_backend(mjx_jax_runs, cpu_runs):
    assert not mjx_jax_runs["split-tee"].rigid.any() and not cpu_runs[("split-tee", "cylinder")].rigid.any()
    assert np.all(mjx_jax_runs["split-tee"].gap_max_dev >= 0.03)


SHARD_SCRIPT = """
import numpy as np, jax
from mjx_pusht.backends.mjx import MjxBackend
from mjx_pusht.scenario import Scenario
assert len(jax.devices()) == 2, jax.devices()
seeds = np.arange(8)
one = MjxBackend(Scenario(), "warp", devices=jax.devices()[:1]).run(seeds)
two = MjxBackend(Scenario(), "warp", devices=jax.devices())
assert two.device.endswith(" x2"), two.device
two = two.run(seeds)
for name, a in one.columns().items():
    np.testing.assert_array_equal(a, two.columns()[name], err_msg=name)
print("SHARDED_OK")
"""


TWO_CPU_DEVICES = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"}


@pytest.mark.slow
@pytest.mark.warp
def test_mjx_warp_over_two_devices_runs_a_program_on_each_and_gives_identical_rows():
    # A program a device, each on its own worlds (launch.per_device: XLA cannot partition MJX-Warp's FFI call, and
    # MJX-JAX's rollout shard_map'd over 4 H200s crashed XLA's compile). Warp's kernels are per world, so the rows are
    # bit-identical. MJX-JAX takes the same path (benchmarks' two-device harness test runs it; its x64 equality test
    # was 86 s of the suite for a path this one covers).
    r = subprocess.run([sys.executable, "-c", SHARD_SCRIPT], capture_output=True, text=True, env=TWO_CPU_DEVICES)
    assert "SHARDED_OK" in r.stdout, r.stderr[-2000:]


class _StopAfter(Backend):
    """A backend that stops the sweep (like Ctrl-C) after `n` chunks."""

    def __init__(self, inner, n):
        self.inner, self.n = inner, n
        self.name, self.default_chunk = inner.name, inner.default_chunk
        self.scenario, self.simulated_scene, self.model, self.devices = inner.scenario, inner.simulated_scene, inner.model, inner.devices

    @property
    def compile_seconds(self):
        return self.inner.compile_seconds

    def run(self, seeds, **kw):
        if self.n == 0:
            raise KeyboardInterrupt
        self.n -= 1
        return self.inner.run(seeds, **kw)


def test_a_sweep_killed_after_a_chunk_resumes_to_the_same_table(tmp_path):
    seeds = np.arange(10)
    backend = CpuBackend(Scenario())
    config = {"backend": "cpu", "break_it": "none", "steps": 120}
    whole = run_sweep(backend, seeds, tmp_path / "whole", config=config, chunk=4, progress=False)
    cut = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(_StopAfter(backend, 1), seeds, cut, config=config, chunk=4, progress=False)
    assert not (cut / "per_seed.parquet").exists()  # no half table, only finished chunks
    assert len(list((cut / ".parts").glob("seeds-*.parquet"))) == 1
    resumed = run_sweep(backend, seeds, cut, config=config, chunk=4, resume=True, progress=False)
    finish(cut, resumed)
    finish(tmp_path / "whole", whole)
    a, b = read_table(tmp_path / "whole" / "per_seed.parquet"), read_table(cut / "per_seed.parquet")
    for k in COLUMNS:
        np.testing.assert_array_equal(a[k], b[k])


def test_unfinished_sweep_is_not_clobbered_without_resume(tmp_path, capsys):
    seeds = np.arange(10)
    config = {"backend": "cpu", "break_it": "none", "steps": 120}
    with pytest.raises(KeyboardInterrupt):
        run_sweep(_StopAfter(CpuBackend(Scenario()), 1), seeds, tmp_path, config=config, chunk=4, progress=False)
    assert main(["sweep", "--seeds", "10", "--backend", "cpu", "--out", str(tmp_path), "--no-rerun"]) == 1
    assert "--resume" in capsys.readouterr().err
    assert main(["sweep", "--seeds", "11", "--backend", "cpu", "--out", str(tmp_path), "--resume", "--no-rerun"]) == 1
    assert "other seeds" in capsys.readouterr().err
    assert len(list((tmp_path / ".parts").glob("seeds-*.parquet"))) == 1


def test_non_finite_seeds_are_flagged_and_counted_not_averaged(tmp_path):
    import copy

    import mujoco

    from mjx_pusht.model.layout import QposLayout
    from mjx_pusht.model.params import warning_bits
    from mjx_pusht.study.sweep import summarize
    from mjx_pusht.task.reset import start_poses

    backend = CpuBackend(Scenario())
    backend.model = m = copy.copy(backend.model)  # a copy: the compiled model is cached for every other test
    m.dof_damping[:2] = -8.0  # anti-damping: once pushed, the tee's speed grows without bound
    rows = backend.run(np.arange(3))
    # the reference: the chapter's own mj_step loop per seed, and what MuJoCo's counters say
    controller, episode = Scenario().driver()
    table = controller.open_loop(episode.max_steps, 1)
    finite, warned = [], []
    for q0 in QposLayout.of(m).initial_qpos(m, start_poses(np.arange(3), reset="chapter")):
        d = mujoco.MjData(m)
        d.qpos[:] = q0
        ok = True
        for u in table:
            d.ctrl[:] = u
            mujoco.mj_step(m, d)
            ok &= bool(np.all(np.isfinite(d.qpos)) and np.all(np.abs(d.qvel) < mujoco.mjMAXVAL))
        finite.append(ok)
        warned.append(warning_bits(d))
    assert not any(finite) and all(warned)  # every seed blows up, and MuJoCo warns about it (BADQACC)
    np.testing.assert_array_equal(rows.finite, finite)
    np.testing.assert_array_equal(rows.warnings, warned)  # mujoco.rollout stops at a warning; the rows do not
    assert not rows.rigid.any()
    s = summarize(rows, backend=backend, schedule=Scenario().schedule, break_it="none", compile_s=0, run_s=1)
    assert s["n_non_finite"] == 3 and s["non_finite_seeds"] == [0, 1, 2] and s["gap_max_dev"]["n"] == 0
    assert s["n_mujoco_warnings"] == 3 and "mjWARN_BADQACC" in s["mujoco_warnings"]
    # MuJoCo itself noticed, in its log in the working folder (the test's own, conftest): QACC blew up
    log = (tmp_path / "MUJOCO_LOG.TXT").read_text()
    assert "Nan, Inf or huge value in QACC" in log


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--seeds", "abc"], "not an integer"),
        (["--seeds", "9:3"], "empty range"),
        (["--seeds", "0"], "empty sweep"),
        (["--backend", "gpu-magic"], "unknown backend"),
    ],
)
def test_bad_sweep_input_is_one_line(tmp_path, capsys, argv, needle):
    assert main(["sweep", *argv, "--out", str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err.strip()
    assert needle in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_mjx_warp_without_warp_lang_is_one_line(tmp_path, capsys, monkeypatch):
    import mjx_pusht.backends.mjx as rm

    monkeypatch.setattr(rm, "warp_available", lambda: False)
    assert main(["sweep", "--seeds", "2", "--backend", "mjx-warp", "--out", str(tmp_path / "o")]) == 1
    assert "warp-lang" in capsys.readouterr().err


def test_sweep_cli_writes_table_summary_and_recording(tmp_path):
    out = tmp_path / "s"
    r = subprocess.run([sys.executable, "-m", "mjx_pusht", "sweep", "--seeds", "6", "--backend", "cpu", "--out", str(out),
                        "--record", "2"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    s = json.loads((out / "summary.json").read_text())
    for key in ("backend", "device", "versions", "pusher_shape", "n_seeds", "steps", "break_it", "rigid_fraction",
                "gap_max_dev", "n_non_finite", "compile_seconds", "run_seconds", "steps_per_second"):
        assert key in s
    assert s["n_seeds"] == 6 and s["rigid_fraction"] == 1.0 and s["pusher_shape"] == "cylinder"
    assert (out / "sweep.rrd").stat().st_size > 0 and not (out / ".parts").exists()
    assert "tier:" in r.stdout and "wall-clock" in r.stdout
    # the task's score says what was scored: the nudge's open-loop 120 steps, not a controller (a bare
    # `task.success_rate 0.0` once read as a broken task); the seeds' own table agrees with the rate printed
    import pyarrow.parquet as pq

    rate = float(np.mean(pq.read_table(out / "per_seed.parquet").column("task_success").to_numpy()))
    assert s["task"]["success_rate"] == rate and "nudge" in s["task"]["run"] and "120 steps" in s["task"]["run"]
    assert f"task score: {rate:.1%} of seeds at coverage >= 0.95, after the chapter's nudge" in r.stdout


class _MemoryBound(Backend):
    """A backend whose device "fits" at most `limit` rows: larger batches fail like XLA out of memory."""

    def __init__(self, inner, limit):
        self.inner, self.limit = inner, limit
        self.scenario, self.simulated_scene, self.model, self.devices = inner.scenario, inner.simulated_scene, inner.model, inner.devices
        self.name, self.default_chunk, self.compile_seconds = inner.name, 64, 0.0
        self.batches = []

    def run(self, seeds, batch=None, **kw):
        self.batches.append(batch)
        if batch > self.limit:
            raise RuntimeError("RESOURCE_EXHAUSTED: Out of memory while trying to allocate 16.27GiB")
        return self.inner.run(seeds, batch=batch, **kw)


def test_a_chunk_too_big_for_memory_is_halved_automatically(tmp_path):
    seeds = np.arange(20)
    config = {"backend": "cpu", "break_it": "none", "steps": 120}
    bound = _MemoryBound(CpuBackend(Scenario()), limit=8)
    run = run_sweep(bound, seeds, tmp_path / "a", config=config, chunk=32, progress=False)
    assert bound.batches[:3] == [32, 16, 8] and max(bound.batches[3:]) == 8
    ref = run_sweep(CpuBackend(Scenario()), seeds, tmp_path / "b", config=config, chunk=32, progress=False)
    np.testing.assert_array_equal(run.rollouts.final, ref.rollouts.final)


class _Pipelined(Backend):
    """A backend that works like MJX's: `submit` returns at once (the rollout runs on another thread) and
    `collect` waits for it; optionally out of memory above `limit` rows, or interrupted at the k-th collect."""

    pipelined = True

    def __init__(self, inner, limit=None, stop_at=None):
        from concurrent.futures import ThreadPoolExecutor

        self.inner, self.limit, self.stop_at = inner, limit, stop_at
        self.scenario, self.simulated_scene, self.model, self.devices = inner.scenario, inner.simulated_scene, inner.model, inner.devices
        self.name, self.default_chunk, self.compile_seconds = inner.name, 64, 0.0
        self.pool = ThreadPoolExecutor(1)
        self.in_flight, self.max_in_flight, self.collected = 0, 0, 0

    def submit(self, seeds, batch=None, **kw):
        self.in_flight += 1
        self.max_in_flight = max(self.max_in_flight, self.in_flight)
        return types.SimpleNamespace(batch=batch, future=self.pool.submit(self.inner.run, seeds, batch=batch, **kw))

    def collect(self, p):
        self.in_flight -= 1
        self.collected += 1
        if self.stop_at is not None and self.collected == self.stop_at:
            raise KeyboardInterrupt
        if self.limit is not None and p.batch > self.limit:
            raise RuntimeError("RESOURCE_EXHAUSTED: Out of memory while trying to allocate 16.27GiB")
        return p.future.result()


def test_a_pipelined_sweep_keeps_two_chunks_in_flight_and_writes_the_sequential_table(tmp_path):
    seeds = np.arange(20)
    config = {"backend": "cpu", "break_it": "none", "steps": 120}
    ref = run_sweep(CpuBackend(Scenario()), seeds, tmp_path / "ref", config=config, chunk=4, progress=False)
    piped = _Pipelined(CpuBackend(Scenario()))
    run = run_sweep(piped, seeds, tmp_path / "p", config=config, chunk=4, progress=False)
    assert piped.max_in_flight == 2  # the next chunk was launched before this one was collected
    assert sorted(p.name for p in (tmp_path / "p" / ".parts").glob("seeds-*")) == [
        f"seeds-{lo:012d}-{lo + 4:012d}.parquet" for lo in range(0, 20, 4)]
    for k in COLUMNS:
        np.testing.assert_array_equal(run.table[k], ref.table[k])
    # out of memory at collect: what was in flight is dropped, the chunk halves, the rows are the same
    small = run_sweep(_Pipelined(CpuBackend(Scenario()), limit=4), seeds, tmp_path / "m", config=config, chunk=16,
                      progress=False)
    np.testing.assert_array_equal(small.rollouts.final, ref.rollouts.final)
    # interrupted after two chunks, resumed: the same table
    cut = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(_Pipelined(CpuBackend(Scenario()), stop_at=3), seeds, cut, config=config, chunk=4, progress=False)
    assert len(list((cut / ".parts").glob("seeds-*.parquet"))) == 2
    resumed = run_sweep(_Pipelined(CpuBackend(Scenario())), seeds, cut, config=config, chunk=4, resume=True,
                        progress=False)
    for k in COLUMNS:
        np.testing.assert_array_equal(resumed.table[k], ref.table[k])
