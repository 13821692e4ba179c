"""One sweep over two processes joined by jax.distributed writes the table one process writes, to the bit."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import numpy as np
import pytest

from mjx_pusht.cli.commands import main
from mjx_pusht.io.outputs import read_table


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sweep_args(out, *extra):
    return ["sweep", "--seeds", "40", "--backend", "cpu", "--chunk", "8", "--no-rerun", "--no-progress",
            "--out", str(out), *extra]


def test_two_processes_on_localhost_write_the_one_process_table(tmp_path):
    port = _free_port()
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    common = _sweep_args(tmp_path / "two", "--num-processes", "2", "--coordinator", f"127.0.0.1:{port}")
    procs = [subprocess.Popen([sys.executable, "-m", "mjx_pusht", *common, "--process-id", str(i)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True) for i in (1, 0)]
    logs = [p.communicate(timeout=600)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], logs
    assert "process 1: rows 20..39 written" in logs[0]
    assert main(_sweep_args(tmp_path / "one")) == 0
    two, one = read_table(tmp_path / "two" / "per_seed.parquet"), read_table(tmp_path / "one" / "per_seed.parquet")
    assert list(two) == list(one)
    for k in one:
        np.testing.assert_array_equal(two[k], one[k], err_msg=k)
    assert not (tmp_path / "two" / ".parts").exists()  # process 0 merged the chunks and cleaned up


@pytest.mark.parametrize("argv, needle", [
    (["--num-processes", "2", "--process-id", "2", "--coordinator", "127.0.0.1:1"], "--process-id must be from 0 to 1"),
    (["--num-processes", "2", "--process-id", "1"], "need --coordinator"),
    (["--num-processes", "2", "--coordinator", "nowhere"], "HOST:PORT"),
])
def test_bad_process_options_are_one_line(tmp_path, capsys, argv, needle):
    assert main(_sweep_args(tmp_path / "x", *argv)) == 1
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
