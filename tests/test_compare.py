"""Comparison of MJX with the CPU reference: outcome distances and modes, and a small compare run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mjx_pusht.backends.results import Rollouts
from mjx_pusht.study.outcomes import energy_distance, outcome_modes


def test_energy_distance_is_zero_for_identical_samples_and_grows_with_a_shift():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(300, 3))
    assert energy_distance(a, a) == pytest.approx(0.0, abs=1e-12)
    # for two point masses the energy distance is exactly 2|d|
    assert energy_distance(np.zeros((5, 3)), np.full((5, 3), [0.0, 0.0, 0.5])) == pytest.approx(1.0)


def test_outcome_modes_split_on_final_yaw():
    z = np.zeros((4, 3))
    final = np.array([[0, 0, 0.1], [0, 0, 1.2], [0, 0, -1.2], [0, 0, -0.2]])
    r = Rollouts(np.arange(4), z, z, final, np.zeros((4, 2)), np.zeros(4), np.zeros(4), np.ones(4, bool), np.ones(4, bool))
    assert outcome_modes(r) == {"straight": 0.5, "spun_ccw": 0.25, "spun_cw": 0.25}


@pytest.mark.slow
def test_compare_on_a_few_seeds_agrees_where_it_must(tmp_path):
    from mjx_pusht.cli.commands import main

    assert main(["compare", "--seeds", "6", "--backend", "mjx-jax", "--out", str(tmp_path), "--no-root-cause"]) == 0
    r = json.loads((tmp_path / "compare.json").read_text())
    for variant in ("none", "split-tee"):
        assert r[variant]["settle_max_abs_err"] <= 1e-5
        assert r[variant]["verdict_agreement"] == 1.0
    assert r["none"]["structure"]["pusher_shape"] == "capsule"
    assert isinstance(r["outcomes"]["outcome_within_cpu_baseline"], bool)
    assert "# CPU vs mjx-jax" in (tmp_path / "compare.md").read_text()
    assert (tmp_path / "compare.png").read_bytes()[:4] == b"\x89PNG"


# --- the task score -------------------------------------------------------------


# --- compare --evals: a transfer report from two machines' evals --------------------------------

_EVAL = ["eval", "--controller", "expert", "--reset", "chapter", "--max-steps", "60", "--no-rerun", "--no-progress"]


@pytest.fixture(scope="module")
def cpu_eval(tmp_path_factory):
    """The expert on MuJoCo C, seeds 0..5: the rows every pairing below starts from."""
    from mjx_pusht.cli.commands import main

    out = tmp_path_factory.mktemp("cpu-eval")
    assert main([*_EVAL, "--backend", "cpu", "--seeds", "6", "--out", str(out)]) == 0
    return out


def _as_mjx(src, dst, *, flip=(), order=None, **config):
    """`src`'s eval folder as if MJX had run it: rows reordered by `order`, the success verdicts of the
    seeds in `flip` turned over, config entries replaced."""
    import shutil

    from mjx_pusht.io.outputs import atomic_write_table, read_table

    shutil.copytree(src, dst)
    s = json.loads((dst / "summary.json").read_text())
    s["backend"] = s["config"]["backend"] = "mjx-jax"
    s["config"].update(config)
    (dst / "summary.json").write_text(json.dumps(s))
    t = read_table(dst / "per_episode.parquet")
    for seed in flip:
        t["success"][t["seed"] == seed] ^= True
    idx = np.arange(len(t["seed"])) if order is None else np.asarray(order)
    atomic_write_table(dst / "per_episode.parquet", {k: v[idx] for k, v in t.items()})
    return dst


def test_two_evals_pair_seed_by_seed_whatever_order_their_rows_are_in(cpu_eval, tmp_path):
    from mjx_pusht.cli.commands import main
    from mjx_pusht.io.outputs import read_table

    cpu = read_table(cpu_eval / "per_episode.parquet")
    flip = (1, 4)
    mjx = _as_mjx(cpu_eval, tmp_path / "mjx", flip=flip, order=[5, 3, 1, 0, 2, 4])
    assert main(["compare", "--evals", str(mjx), str(cpu_eval), "--out", str(tmp_path / "r")]) == 0
    r = json.loads((tmp_path / "r" / "compare_episodes.json").read_text())
    d = r["success_difference_mjx_minus_cpu"]
    # counted by hand: a flipped seed that succeeded on the CPU succeeds only there, and the other way round
    ok = dict(zip(cpu["seed"].tolist(), cpu["success"].tolist()))
    only_cpu, only_mjx = sum(ok[s] for s in flip), sum(not ok[s] for s in flip)
    diff, se = (only_mjx - only_cpu) / 6, np.sqrt(only_mjx + only_cpu - (only_mjx - only_cpu) ** 2 / 6) / 6
    assert (d["only_mjx"], d["only_cpu"]) == (only_mjx, only_cpu) and d["difference"] == pytest.approx(diff)
    assert d["ci95"] == pytest.approx([diff - 1.959964 * se, diff + 1.959964 * se])
    assert r["per_seed_success_agreement"]["mjx_vs_cpu"] == pytest.approx(4 / 6)
    # the reordered rows were put back in seed order: the same final poses, seed for seed
    assert r["final_pose_diff"]["mjx_vs_cpu"]["max_m"] == 0.0
    assert r["mjx"]["n_success"] == r["cpu"]["n_success"] + only_mjx - only_cpu and r["cpu_f32_starts"] is None
    md = (tmp_path / "r" / "compare_episodes.md").read_text()
    assert "Paired from two evals" in md and "float32-rounded starts: the chaos yardstick is not" in md


@pytest.mark.parametrize("change, says", [
    ({"max_steps": 61}, "differ in max_steps"),
    ({"controller": "nudge"}, "differ in controller"),
    ({"controller_sha256": "0" * 64, "reset": "task"}, "differ in reset"),
    ({"task": "gym-pusht", "action": "target", "reset": "gym-pusht"}, "differ in task"),  # the cause, not its action
])
def test_evals_of_other_episodes_are_refused_in_one_line(cpu_eval, tmp_path, capsys, change, says):
    from mjx_pusht.cli.commands import main

    mjx = _as_mjx(cpu_eval, tmp_path / "mjx", **change)
    assert main(["compare", "--evals", str(cpu_eval), str(mjx), "--out", str(tmp_path / "r")]) != 0
    err = capsys.readouterr().err.strip()
    assert says in err and "\n" not in err and not (tmp_path / "r").exists()  # checked before --out is made


def test_evals_of_other_seeds_two_cpu_runs_or_a_sweep_are_refused_in_one_line(cpu_eval, tmp_path, capsys):
    from mjx_pusht.cli.commands import main
    from mjx_pusht.io.outputs import read_table

    n = len(read_table(cpu_eval / "per_episode.parquet")["seed"])
    fewer = _as_mjx(cpu_eval, tmp_path / "fewer", order=range(n - 1))
    assert main(["compare", "--evals", str(cpu_eval), str(fewer), "--out", str(tmp_path / "a")]) != 0
    assert "ran other seeds" in capsys.readouterr().err
    assert main(["compare", "--evals", str(cpu_eval), str(cpu_eval), "--out", str(tmp_path / "b")]) != 0
    assert "these ran on cpu and cpu" in capsys.readouterr().err
    assert main(["compare", "--evals", str(cpu_eval), str(tmp_path), "--out", str(tmp_path / "c")]) != 0
    assert "is not a finished eval folder" in capsys.readouterr().err
    assert main(["compare", "--evals", str(cpu_eval), str(fewer), "--controller", "expert",
                 "--out", str(tmp_path / "d")]) == 2
    assert "--controller is not taken" in capsys.readouterr().err
    (fewer / "per_episode.parquet").write_bytes(b"cut short")
    assert main(["compare", "--evals", str(cpu_eval), str(fewer), "--out", str(tmp_path / "e")]) != 0
    err = capsys.readouterr().err.strip()
    assert "is not an eval's table" in err and "\n" not in err
    assert not any((tmp_path / d).exists() for d in "abcde")  # each refused before its --out was made


def test_an_eval_of_a_policy_records_its_files_hash_and_pairing_checks_it(tmp_path, capsys):
    import hashlib
    import shutil
    from pathlib import Path

    from mjx_pusht.cli.commands import main

    policy = Path(__file__).resolve().parents[1] / "outputs/reports/train/ppo-state/policy.msgpack"
    shutil.copy(policy, tmp_path / "p.msgpack")
    args = ["eval", "--controller", "policy:p.msgpack", "--reset", "task", "--seeds", "2", "--max-steps", "5",
            "--no-rerun", "--no-progress", "--backend", "cpu"]
    assert main([*args, "--out", str(tmp_path / "c")]) == 0
    s = json.loads((tmp_path / "c" / "summary.json").read_text())
    assert s["config"]["controller_sha256"] == hashlib.sha256(policy.read_bytes()).hexdigest()
    # the same path holding other weights on the "MJX" machine: the hashes differ, and that is refused
    mjx = _as_mjx(tmp_path / "c", tmp_path / "m", controller_sha256="f" * 64)
    assert main(["compare", "--evals", str(tmp_path / "c"), str(mjx), "--out", str(tmp_path / "r")]) != 0
    assert "differ in controller_sha256" in capsys.readouterr().err
