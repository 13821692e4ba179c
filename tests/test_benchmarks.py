"""The benchmark harness runs and writes valid results (a functional test, not a timing)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import harness, table


def test_harness_runs_at_tiny_sizes_and_writes_json_and_plot(tmp_path):
    assert harness.main(["--tier", "tiny", "--backends", "cpu", "--batches", "4,8", "--repeats", "1",
                         "--e2e", "16", "--e2e-backend", "cpu", "--out", str(tmp_path)]) == 0
    r = json.loads((tmp_path / "tiny.json").read_text())
    rows = r["backends"]["cpu"]["rows"]
    assert [row["batch"] for row in rows] == [4, 8]
    assert all(row["steps_per_second"] > 0 and row["run_seconds_median"] > 0 for row in rows)
    assert r["cpu_single_thread_mj_step_per_second"] > 0
    # the versions recorded are the ones running, each inside the range pyproject.toml declares
    import jax
    import mujoco
    import tomllib
    from packaging.requirements import Requirement

    assert r["versions"]["mujoco"] == mujoco.__version__ and r["versions"]["jax"] == jax.__version__
    declared = {req.name: req.specifier for req in map(Requirement, tomllib.loads(
        (table.ROOT / "pyproject.toml").read_text())["project"]["dependencies"])}
    for pkg in ("mujoco", "mujoco-mjx", "jax", "jaxlib", "numpy"):
        assert declared[pkg].contains(r["versions"][pkg]), (pkg, r["versions"][pkg], declared[pkg])
    assert r["end_to_end"]["n_seeds"] == 16 and r["end_to_end"]["rigid_fraction"] == 1.0
    assert (tmp_path / "tiny.png").read_bytes()[:4] == b"\x89PNG"


def test_harness_records_a_backend_that_cannot_run_instead_of_crashing(tmp_path):
    assert harness.main(["--tier", "t", "--backends", "no-such-backend", "--out", str(tmp_path)]) == 0
    assert "error" in json.loads((tmp_path / "t.json").read_text())["backends"]["no-such-backend"]


def test_the_benchmarks_page_table_is_rendered_from_the_committed_results():
    page = table.PAGE.read_text()
    block = page[page.index(table.BEGIN) + len(table.BEGIN): page.index(table.END)].strip()
    assert block == table.render().strip()


@pytest.mark.slow
def test_harness_measures_a_backend_sharded_over_two_devices_with_its_scaling(tmp_path):
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2", "JAX_PLATFORMS": "cpu"}
    r = subprocess.run([sys.executable, "-m", "benchmarks.harness", "--tier", "two", "--backends", "mjx-jax",
                        "--batches", "4", "--repeats", "1", "--device-counts", "1,2", "--out", str(tmp_path)],
                       capture_output=True, text=True, env=env, cwd=table.ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
    b = json.loads((tmp_path / "two.json").read_text())["backends"]
    assert b["mjx-jax"]["devices"] == 1 and b["mjx-jax-x2"]["devices"] == 2
    assert b["mjx-jax-x2"]["device"].endswith(" x2")
    one, two = b["mjx-jax"]["rows"][0]["steps_per_second"], b["mjx-jax-x2"]["rows"][0]["steps_per_second"]
    assert b["mjx-jax-x2"]["scaling_efficiency"]["4"] == pytest.approx(two / (2 * one), abs=1e-3)


@pytest.mark.slow
@pytest.mark.warp
def test_env_loop_times_the_env_against_the_raw_physics_of_the_same_worlds_each_compiled_once(tmp_path):
    """benchmarks.env_loop at 8 envs on Warp's CPU device: every case runs, its timed call compiled nothing
    (a second compile was once timed as stepping: notebook change 16), the ratio is against `raw`, and the
    autoreset case resets: its episodes of --ends steps end in the timed steps, each row every `ends` steps (issue
    57: at 300-step episodes its "with autoreset" figure reset nothing)."""
    from benchmarks import env_loop

    out = tmp_path / "loop.json"
    assert env_loop.main(["--envs", "8", "--steps", "2", "--ends", "1", "--cases", "raw,scan_autoreset,gym_numpy",
                          "--json", str(out)]) == 0
    row = json.loads(out.read_text())["runs"][0]["rows"][0]
    assert "error" not in row, row
    assert row["raw"]["compiles"] == 1 and row["scan_autoreset"]["compiles"] == 1
    for case in ("raw", "scan_autoreset", "gym_numpy"):
        assert row[case]["control_steps_per_s"] > 0
    r = row["scan_autoreset"]
    assert r["episodes_reset"] == 8 * 2  # 8 rows, each ending at both timed steps
    assert r["fraction_of_raw"] == pytest.approx(r["control_steps_per_s"] / row["raw"]["control_steps_per_s"])


def test_train_seeds_reports_every_committed_seed_run_and_their_spread(tmp_path):
    """The committed DAgger-from-state runs (seed 0; seed 1, last and best) aggregated as one result: each row is
    eval's held-out count over its episodes, the mean / sd / min are those of the three rates, and a run folder
    without a finished eval, or without a summary at all, is listed as failed (exit 1), not dropped or averaged in."""
    import numpy as np

    from benchmarks import train_seeds

    root = Path(__file__).resolve().parents[1] / "outputs" / "reports" / "train"
    runs = [root / "dagger-state", root / "history" / "dagger-state-change24-seed1",
            root / "history" / "dagger-state-change28-seed1-keep-best"]
    cut = tmp_path / "cut"
    cut.mkdir()
    s = json.loads((runs[0] / "summary.json").read_text())
    del s["eval"]
    (cut / "summary.json").write_text(json.dumps(s))
    gone = tmp_path / "gone"  # a run cut off with its machine: its first fits written, no summary
    gone.mkdir()
    (gone / "first_fits.json").write_text('{"kept": 0, "losses": [0.003]}')
    rc = train_seeds.main(["--collect", *map(str, runs), str(cut), str(gone), "--out", str(tmp_path / "agg"),
                           "--goal", "0.95"])
    assert rc == 1
    out = json.loads((tmp_path / "agg" / "seeds.json").read_text())
    evals = [json.loads((r / "summary.json").read_text())["eval"] for r in runs]
    rates = np.array([e["n_success"] / e["n_episodes"] for e in evals])
    assert [r["held_out_success"] for r in out["runs"]] == list(rates)
    agg = out["aggregate"]
    assert agg["n_seeds"] == 3 and agg["mean"] == pytest.approx(rates.mean()) and agg["min"] == rates.min()
    assert agg["sd"] == pytest.approx(rates.std(ddof=1)) and agg["seeds_at_goal"] == int((rates >= 0.95).sum())
    assert len(out["failed"]) == 2 and "cut" in out["failed"][0] and "did not finish" in out["failed"][0]
    assert "gone" in out["failed"][1] and "no summary.json: the run did not finish" in out["failed"][1]
    table_rows = [line for line in (tmp_path / "agg" / "seeds.md").read_text().splitlines() if line[:3] in ("| 0", "| 1")]
    assert len(table_rows) == 3  # every run, the two of seed 1 included


def test_train_seeds_names_a_collapse_the_curve_recovered_from():
    """`low_after` is the lowest held-out judgement later than the first at or above 80%: the committed unclipped PPO
    runs (their collapses) fell below 10% after it; the clipped ones (the default since) never left 99%."""
    from benchmarks import train_seeds

    root = Path(__file__).resolve().parents[1] / "outputs" / "reports" / "train"
    assert train_seeds.low_after([{"success": s} for s in (0.1, 0.5, 0.85, 0.3, 0.9)]) == 0.3
    assert train_seeds.low_after([{"success": s} for s in (0.1, 0.79)]) is None
    assert train_seeds.low_after([{"success": s} for s in (0.1, 0.85)]) is None  # no judgement after it
    for folder, bound in (("history/ppo-state-unclipped", lambda low: low < 0.1),
                          ("ppo-state-seeds", lambda low: low > 0.99)):
        for run in sorted((root / folder).glob("seed-*")):
            curve = json.loads((run / "summary.json").read_text())["curve"]
            assert bound(train_seeds.row(run)["low_after"]), (run, [r["success"] for r in curve])


@pytest.mark.slow  # the fast loop keeps the ring's own tests (test_dagger_ring.py); this times the benchmark
def test_dagger_host_work_measures_the_ring_and_the_checkpoint_at_tiny_sizes(tmp_path):
    """benchmarks/dagger_host_work.py runs at tiny sizes: one row per iteration, samples of different counts and no
    program compiled after the first iteration; the checkpoint's writer timed beside a main-thread loop."""
    from benchmarks import dagger_host_work

    out = tmp_path / "host.json"
    assert dagger_host_work.main(["--envs", "16", "--samples", "20000", "--iterations", "3", "--ring-samples",
                                  "10000", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert [r["compiled"] for r in result["ring"]][1:] == [0, 0] and len({r["samples"] for r in result["ring"]}) == 3
    from mjx_pusht.train.dagger import DaggerConfig

    c = result["checkpoint"]
    assert c["ring_bytes"] == 10000 * 4 * (DaggerConfig().sample_width + 3)  # float32 samples and labels
    assert c["writer_seconds"] > 0 and c["steps_per_s_alone"] > 0


def test_train_scaling_times_each_device_counts_run_against_one_devices(tmp_path):
    """benchmarks/train_scaling.py on finished runs (read, not run again): the committed DAgger-from-state run as the
    1-device run and, as a 2-device run, the same run at half its wall-clock: twice the control steps a second, the
    goal rate reached in half the minutes, each from the summary's own curve."""
    from benchmarks import train_scaling

    s = json.loads((Path(__file__).resolve().parents[1] / "outputs" / "reports" / "train" / "dagger-state" /
                    "summary.json").read_text())
    for n in (1, 2):
        (tmp_path / f"devices-{n}").mkdir()
        (tmp_path / f"devices-{n}" / "summary.json").write_text(json.dumps(
            s | {"devices": n, "wall_seconds": s["wall_seconds"] / n,
                 "curve": [r | {"wall_seconds": r["wall_seconds"] / n} for r in s["curve"]]}))
    assert train_scaling.main(["--devices", "1,2", "--goal", "0.9", "--out", str(tmp_path)]) == 0
    one, two = json.loads((tmp_path / "scaling.json").read_text())["runs"]
    assert one["steps_per_second"] == pytest.approx(s["env_steps"] / s["wall_seconds"])
    assert two["steps_per_second"] == pytest.approx(2 * one["steps_per_second"])
    first = next(r for r in s["curve"] if r["success"] >= 0.9)
    assert one["minutes_to_goal"] == pytest.approx(first["wall_seconds"] / 60) == 2 * two["minutes_to_goal"]
    assert two["steady_steps_per_second"] == pytest.approx(2 * one["steady_steps_per_second"])
    assert "| 2 | " in (tmp_path / "scaling.md").read_text() and "| 2.00 |" in (tmp_path / "scaling.md").read_text()
    # the mode is the runs' own: both ran the same episodes, so the one run's work was split (strong)
    envs = s["config"]["envs"]
    made = json.loads((tmp_path / "scaling.json").read_text())
    assert made["scaling"] == f"strong: the one run's {envs:,} episodes split over the devices"
    # counts run apart (a process each, started by hand, lead30) are collected in the mode they ran in, read from
    # the runs' own episode counts, whatever the recipe declared: here 2 devices ran twice one device's episodes
    two_s = json.loads((tmp_path / "devices-2" / "summary.json").read_text())
    (tmp_path / "devices-2" / "summary.json").write_text(json.dumps(two_s | {"config": two_s["config"] | {
        "envs": 2 * envs}}))
    (tmp_path / "scaling.json").write_text(json.dumps(made | {"train_args": ["--envs", "64"], "per_device": []}))
    assert train_scaling.main(["--devices", "1,2", "--goal", "0.9", "--out", str(tmp_path), "--collect"]) == 0
    again = json.loads((tmp_path / "scaling.json").read_text())
    assert again["scaling"] == f"weak: {envs:,} episodes per device" and again["train_args"] == ["--envs", "64"]
    assert [r["steps_per_second"] for r in again["runs"]] == [r["steps_per_second"] for r in made["runs"]]
    assert (tmp_path / "scaling.md").read_text().endswith(f"weak: {envs:,} episodes per device\n")
    # runs that wrote no episode count: the declared recipe's mode
    for n in (1, 2):
        bare = json.loads((tmp_path / f"devices-{n}" / "summary.json").read_text())
        (tmp_path / f"devices-{n}" / "summary.json").write_text(json.dumps(
            bare | {"config": {k: v for k, v in bare["config"].items() if k != "envs"}}))
    (tmp_path / "scaling.json").write_text(json.dumps(made | {"train_args": ["--envs", "64"], "per_device": ["envs"]}))
    assert train_scaling.main(["--devices", "1,2", "--goal", "0.9", "--out", str(tmp_path), "--collect"]) == 0
    assert json.loads((tmp_path / "scaling.json").read_text())["scaling"] == "weak: --envs per device"
    (tmp_path / "scaling.json").write_text("{")  # cut short: argparse's one line, not a traceback
    with pytest.raises(SystemExit):
        train_scaling.main(["--devices", "1,2", "--goal", "0.9", "--out", str(tmp_path), "--collect"])


def test_the_rate_after_the_first_epoch_leaves_its_compile_out_and_nothing_else(tmp_path):
    """A committed PPO run (Brax on 4 H200s) and the same run whose first epoch took 100 s longer (a slower compile):
    the whole run's rate drops, the rate after the first epoch is unchanged, and it is the later epochs' own steps
    over their own seconds."""
    from benchmarks import train_scaling

    s = json.loads((Path(__file__).resolve().parents[1] / "outputs" / "reports" / "train" / "devices-warp-h200" /
                    "ppo-s1" / "devices-4" / "summary.json").read_text())
    (tmp_path / "a").mkdir(), (tmp_path / "b").mkdir()
    (tmp_path / "a" / "summary.json").write_text(json.dumps(s))
    slow = [dict(c) for c in s["curve"]]
    slow[1]["learn_seconds"] += 100
    (tmp_path / "b" / "summary.json").write_text(json.dumps(s | {"curve": slow,
                                                                  "learning_seconds": s["learning_seconds"] + 100}))
    a, b = train_scaling.measure(tmp_path / "a", 0.95), train_scaling.measure(tmp_path / "b", 0.95)
    assert b["steps_per_second"] < 0.5 * a["steps_per_second"]
    assert b["steady_steps_per_second"] == a["steady_steps_per_second"]
    epochs = s["curve"][2:]
    assert a["steady_steps_per_second"] == pytest.approx(
        (len(epochs) * (s["curve"][1]["env_steps"] - s["curve"][0]["env_steps"])) / sum(c["learn_seconds"] for c in epochs))


def test_the_diffusion_curve_reads_a_real_lerobot_train_log_past_a_thousand_steps():
    """lerobot-train's own log of the H100 run (tests/data, from outputs/reports/lerobot-diffusion-h100): past 999
    it writes counts as format_big_number does ("step:5K"); the curve reads them back, and its last step is the last
    eval's exact one (5200 of 5255)."""
    from benchmarks.diffusion_curve import parse_run

    log = Path(__file__).with_name("data") / "lerobot-train-diffusion-2000-h100.txt"
    run = parse_run([log])
    steps = [p["step"] for p in run["losses"]]
    assert steps[:10] == list(range(100, 1001, 100)) and steps[-1] == 5000 and steps == sorted(steps)
    assert [p["step"] for p in run["points"]] == [1300, 2600, 3900, 5200] and run["last_step"] == 5200
    assert all(p["n_episodes"] == 50 and p["successes"] == 0 for p in run["points"])
    assert 13 < run["train_min"] < run["wall_min"] < 20  # the evals' minutes left out of the training's


def test_a_run_started_from_another_runs_checkpoint_continues_its_curve(tmp_path, capsys):
    """`--after NAME=MINUTES,STEPS` (a run started FROM a checkpoint taken after that much training): the run's
    points sit that much later in minutes and updates, the same successes; a malformed offset or an unknown run is
    a one-line error and no file is written."""
    from benchmarks.diffusion_curve import main, parse_run

    log = Path(__file__).with_name("data") / "lerobot-train-diffusion-2000-h100.txt"
    alone = parse_run([log])
    out = tmp_path / "curve.json"
    assert main([f"2000={log}", "--after", "2000=12.5,8000", "--json", str(out)]) == 0
    run = json.loads(out.read_text())["2000"]
    assert run["after"] == {"train_min": 12.5, "steps": 8000}
    assert [p["step"] for p in run["points"]] == [8000 + p["step"] for p in alone["points"]] == [9300, 10600, 11900, 13200]
    assert [p["train_min"] for p in run["points"]] == pytest.approx([12.5 + p["train_min"] for p in alone["points"]])
    assert [p["successes"] for p in run["points"]] == [p["successes"] for p in alone["points"]]
    assert run["last_step"] == 13200 and run["train_min"] == pytest.approx(12.5 + alone["train_min"])
    for bad in ("2000=12.5", "2000=x,8000", "200=12.5,8000"):
        with pytest.raises(SystemExit):
            main([f"2000={log}", "--after", bad, "--json", str(tmp_path / "bad.json")])
        assert "--after" in capsys.readouterr().err.splitlines()[-1]
    assert not (tmp_path / "bad.json").exists()
    with pytest.raises(SystemExit):  # a log that is not there: one line, not a traceback
        main([f"2000={tmp_path / 'none.log'}", "--json", str(tmp_path / "bad.json")])
    assert "no log file" in capsys.readouterr().err.splitlines()[-1]
    assert not (tmp_path / "bad.json").exists()


def test_train_scaling_per_device_flags_grow_with_the_devices_and_a_missing_one_is_refused(tmp_path):
    """Weak scaling (`--per-device envs,batch`): each count's run gets those flags times the count, the last value
    of a repeated flag being the one argparse keeps; a flag absent from the train arguments is a one-line error
    before anything runs."""
    from benchmarks import train_scaling

    args = ["--algo", "ppo", "--envs", "8192", "--batch", "256", "--batch", "512", "--minutes", "3"]
    assert train_scaling.per_device(args, ["envs", "batch"], 4) == [
        "--algo", "ppo", "--envs", "32768", "--batch", "256", "--batch", "2048", "--minutes", "3"]
    assert train_scaling.per_device(args, [], 4) == args
    with pytest.raises(SystemExit, match="no --timesteps VALUE"):
        train_scaling.main(["--devices", "1,2", "--goal", "0.9", "--out", str(tmp_path / "r"),
                            "--per-device", "envs,timesteps", "--", *args])
    assert not (tmp_path / "r").exists()
    (tmp_path / "file").write_text("kept")
    with pytest.raises(SystemExit):  # --out under a file: argparse's one line, the file kept
        train_scaling.main(["--devices", "1", "--goal", "0.9", "--out", str(tmp_path / "file" / "r"), "--collect"])
    assert (tmp_path / "file").read_text() == "kept"
