"""Parameter sweeps: a grid row equals the scene compiled with that value, on CPU and on MJX."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from mjx_pusht.backends.cpu import run_cpu
from mjx_pusht.cli.commands import main
from mjx_pusht.io.outputs import read_table
from mjx_pusht.model.params import ParamError, parse_param
from mjx_pusht.model.scene import SceneSpec, compile_xml, scene_xml
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.sweep import rows_for


def test_param_specs():
    assert parse_param("kv=5,20,80") == ("kv", [5.0, 20.0, 80.0])
    assert parse_param("tee_mass=0.1:0.3:3") == ("tee_mass", pytest.approx([0.1, 0.2, 0.3]))
    name, draws = parse_param("kv=~1:100:5")
    assert len(draws) == 5 and all(1 <= d < 100 for d in draws) and parse_param("kv=~1:100:5")[1] == draws
    for bad in ("kv", "gain=5", "kv=", "kv=a,b", "kv=-1", "tee_mass=0", "kv=1:2:0", "kv=nan", "kv=~5:1:3"):
        with pytest.raises(ParamError):
            parse_param(bad)


@pytest.mark.parametrize("kv", [5.0, 80.0])
def test_cpu_kv_grid_rows_equal_the_scene_authored_with_that_kv(kv):
    seeds = np.arange(4)
    scenario = Scenario(params=(("kv", (5.0, 80.0)),))
    row_seeds, combos = rows_for(seeds, 2)
    grid_rows = run_cpu(scenario, row_seeds, combos=combos)
    authored = compile_xml(scene_xml(SceneSpec()).replace('kv="20"', f'kv="{kv:g}"'))
    single = run_cpu(Scenario(), seeds, model=authored)
    pick = grid_rows.params["kv"] == kv
    np.testing.assert_array_equal(grid_rows.final[pick], single.final)
    np.testing.assert_array_equal(grid_rows.gap_max_dev[pick], single.gap_max_dev)


def test_a_soft_servo_pushes_less_far():
    # kv sets how hard the servo tracks 1 m/s; with kv=1 the 30 N cap is never the limit and
    # the pusher lags, so after the same 120 steps the block ends further south.
    seeds = np.arange(8)
    row_seeds, combos = rows_for(seeds, 2)
    r = run_cpu(Scenario(params=(("kv", (1.0, 20.0)),)), row_seeds, combos=combos)
    soft, stiff = r.final[combos == 0, 1], r.final[combos == 1, 1]
    assert np.all(soft < stiff - 0.05)


MJX_KV = """
import numpy as np
from mjx_pusht.backends.mjx import MjxBackend
from mjx_pusht.scenario import Scenario
from mjx_pusht.study.sweep import rows_for
seeds = np.arange(4)
rs, combos = rows_for(seeds, 2)
both = MjxBackend(Scenario(params=(("kv", (5.0, 80.0)),)), "jax", x64=True).run(rs, combos=combos)
for k, kv in enumerate((5.0, 80.0)):
    one = MjxBackend(Scenario(params=(("kv", (kv,)),)), "jax", x64=True).run(seeds)
    a, b = both.columns(), one.columns()
    for name in b:
        x, y = a[name][combos == k], b[name]
        if x.dtype == bool or name == "seed":
            np.testing.assert_array_equal(x, y, err_msg=name)
        else:
            np.testing.assert_allclose(x, y, rtol=0, atol=1e-9, err_msg=name)
print("KV_OK")
"""


@pytest.mark.slow
def test_mjx_kv_grid_is_one_batch_with_the_same_rows_as_two_sweeps():
    # float64, so the comparison is not blurred by float32's dependence on the compiled program
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    r = subprocess.run([sys.executable, "-c", MJX_KV], capture_output=True, text=True, env=env)
    assert "KV_OK" in r.stdout, r.stderr[-2000:]


def test_sweep_table_gains_a_column_per_parameter(tmp_path):
    assert main(["sweep", "--seeds", "3", "--backend", "cpu", "--param", "kv=5,20", "--param", "tee_mass=0.105,0.2",
                 "--out", str(tmp_path), "--no-rerun", "--no-progress"]) == 0
    t = read_table(tmp_path / "per_seed.parquet")
    assert len(t["seed"]) == 12
    assert sorted(set(zip(t["param_kv"], t["param_tee_mass"]))) == [(5, 0.105), (5, 0.2), (20, 0.105), (20, 0.2)]


def test_bad_param_is_one_line(tmp_path, capsys):
    assert main(["sweep", "--seeds", "3", "--param", "gain=5", "--out", str(tmp_path / "o")]) != 0
    err = capsys.readouterr().err.strip()
    assert "NAME=VALUES" in err and "\n" not in err and not (tmp_path / "o").exists()


def test_a_param_this_scene_cannot_take_is_refused_before_the_folder_is_claimed(tmp_path, capsys):
    """kp on the chapter's velocity servos: one line, and no run file left in --out (it left .run.json and
    .parts/manifest.json, the check running when the backend built the model)."""
    out = tmp_path / "o"
    assert main(["sweep", "--backend", "cpu", "--seeds", "2", "--steps", "5", "--param", "kp=1", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert "velocity servos" in err and "\n" not in err and not out.exists()
