"""One sweep over two processes joined by jax.distributed writes the table one process writes, to the bit."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest
from helpers import over

from mjx_pusht.cli.commands import main
from mjx_pusht.io.outputs import read_table


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _sweep_args(out, *extra):
    return ["sweep", *over(("--seeds", "40", "--backend", "cpu", "--chunk", "8", "--no-rerun", "--no-progress"),
                           "--out", str(out), *extra)]


def test_two_processes_on_localhost_write_the_one_process_table(tmp_path):
    port = _free_port()
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    common = _sweep_args(tmp_path / "two", "--num-processes", "2", "--coordinator", f"127.0.0.1:{port}")
    # each log to a file, not a pipe: a pipe read one process after the other can fill and stall the unread
    # process while the other waits for it at JAX's shutdown barrier (both abort when it times out)
    files = [open(tmp_path / f"log-{i}.txt", "w+") for i in (1, 0)]
    procs = [subprocess.Popen([sys.executable, "-m", "mjx_pusht", *common, "--process-id", str(i)], env=env,
                              stdout=f, stderr=subprocess.STDOUT, text=True) for i, f in zip((1, 0), files)]
    for p in procs:
        p.wait(timeout=600)
    logs = [(f.seek(0), f.read())[1] for f in files]
    assert [p.returncode for p in procs] == [0, 0], [log[-3000:] for log in logs]  # the tail names an abort's cause
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


def _start(i, out, port, *extra, n=2):
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    return subprocess.Popen([sys.executable, "-m", "mjx_pusht", *_sweep_args(out, "--num-processes", str(n),
                             "--coordinator", f"127.0.0.1:{port}", "--process-id", str(i), *extra)],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_processes_given_other_settings_stop_before_writing_a_mixed_table(tmp_path):
    """A hostile pass found: process 1 ran the split-tee at 60 steps, process 0 the welded tee at 120, both
    exited 0 and the summary said `break none, steps 120` over the mixed rows. Now both stop in one line."""
    port = _free_port()
    procs = [_start(1, tmp_path, port, "--steps", "60", "--break", "split-tee"), _start(0, tmp_path, port)]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [1, 1], errs
    for err in errs:
        assert len(err.strip().splitlines()) == 1 and "other settings" in err and "break_it" in err and "steps" in err
    assert not (tmp_path / "per_seed.parquet").exists() and not (tmp_path / ".parts").exists()


def test_process_0_refusing_the_folder_ends_every_process_in_one_line(tmp_path):
    """Process 0 claims --out for all. Refused there (a user's file in it), it left process 1 waiting for it at the
    chunks' barrier for 24 hours (the fast loop hung so, on process 1's own write probe taken for a user's file:
    notebook lead29). Now both end in one line, process 1's naming process 0's refusal, and the user's file stays."""
    (tmp_path / "notes.txt").write_text("mine")
    port = _free_port()
    procs = [_start(1, tmp_path, port), _start(0, tmp_path, port)]
    errs = [p.communicate(timeout=240)[1] for p in procs]
    assert [p.returncode for p in procs] == [1, 1], errs
    one, zero = (e.strip().splitlines() for e in errs)
    assert len(zero) == 1 and "holds files sweep did not write (notes.txt)" in zero[0]
    assert len(one) == 1 and "process 0 stopped before any work" in one[0] and "notes.txt" in one[0]
    assert sorted(os.listdir(tmp_path)) == ["notes.txt"] and (tmp_path / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize("zero, one, n, needle", [
    ([], [], 3, "num_processes"),  # process 1, told of 3, ran its own block into the table's chunks
    ([], ["--resume"], 2, "resume"),  # process 1's --resume was ignored without a word
    (["--replace"], [], 2, "replace"),
])
def test_flags_given_to_one_process_alone_stop_both_in_one_line(tmp_path, zero, one, n, needle):
    """The fifteenth pass: a flag only process 0 acts on (it claims the folder), or another process count, given to
    one process was not compared; now every process is refused in one line naming it, and nothing is written."""
    port = _free_port()
    out = tmp_path / "out"
    procs = [_start(1, out, port, *one, n=n), _start(0, out, port, *zero)]
    errs = [p.communicate(timeout=240)[1] for p in procs]
    assert [p.returncode for p in procs] == [1, 1], errs
    for err in errs:
        assert len(err.strip().splitlines()) == 1 and "other settings" in err and needle in err, err
    assert not out.exists()


def test_a_refused_resume_over_processes_leaves_no_folder(tmp_path):
    """Process 0 alone makes --out: another process making it too left an empty folder behind when process 0
    refused it (`--resume` with nothing to resume; the fifteenth pass). One process leaves none, and so do two."""
    port = _free_port()
    out = tmp_path / "new" / "out"
    procs = [_start(1, out, port, "--resume"), _start(0, out, port, "--resume")]
    errs = [p.communicate(timeout=240)[1] for p in procs]
    assert [p.returncode for p in procs] == [1, 1], errs
    assert "nothing to resume" in errs[1] and "process 0 stopped before any work" in errs[0]
    assert os.listdir(tmp_path) == []


def test_chunks_of_runs_split_otherwise_are_refused_before_any_row(tmp_path):
    """Chunk files that overlap (rows 3-4 written by two runs of other process counts) were found only after every
    row had run, in a traceback, the other process left waiting for ever (the fifteenth pass). `--resume` refuses
    them at the start, in one line."""
    from mjx_pusht.study.sweep import PARTS, ResumeError, check_resumable, fingerprint

    seeds, config = np.arange(8), {"backend": "cpu", "steps": 20}
    (tmp_path / PARTS).mkdir()
    (tmp_path / PARTS / "manifest.json").write_text(json.dumps(fingerprint(seeds, config)))
    for lo, hi in ((0, 5), (3, 6)):
        (tmp_path / PARTS / f"seeds-{lo:012d}-{hi:012d}.parquet").write_bytes(b"")
    with pytest.raises(ResumeError, match=r"overlap \(rows 3..4 twice\)"):
        check_resumable(tmp_path, seeds, config, resume=True)


def test_a_write_probe_is_no_users_file(tmp_path):
    """A sibling process's writability probe (`.probe-*`, there for an instant while process 1 checks --out) is the
    run's bookkeeping: process 0's claim takes the folder; a user's file beside it is still refused."""
    from mjx_pusht.io.outputs import OutputError, claim_out_dir, stray_files

    (tmp_path / ".probe-x1y2z3").write_bytes(b"")
    assert stray_files(tmp_path, "sweep") == []
    claim_out_dir(tmp_path, "sweep", {"seeds": [0]})
    (tmp_path / "probe-notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="probe-notes.txt"):
        claim_out_dir(tmp_path, "sweep", {"seeds": [0]})


def test_a_coordinator_port_in_use_is_one_line_not_a_segfault(tmp_path):
    """Finding 6: a port another program listens on made process 0 segfault (exit 139)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("", 0))
        s.listen()
        port = s.getsockname()[1]
        p = _start(0, tmp_path, port)
        _, err = p.communicate(timeout=120)
    assert p.returncode == 1 and len(err.strip().splitlines()) == 1 and f"port {port} is in use" in err


def test_a_missing_process_is_a_timeout_in_one_line(tmp_path):
    """Finding 6: only one of two processes started: a silent 300 s wait, then a C++ Check failure (134)."""
    import time

    t0 = time.time()
    p = _start(0, tmp_path, _free_port(), "--peer-timeout", "3")
    _, err = p.communicate(timeout=120)
    assert p.returncode == 1 and err.strip().splitlines()[-1].startswith("mjx-pusht: error: not all 2 processes")
    assert "Check failure" not in err and time.time() - t0 < 60


def test_sigterm_stops_a_process_joined_by_jax_distributed(tmp_path):
    """JAX's preemption service, on by default with jax.distributed, caught SIGTERM and let the process run on (a
    two-process sweep 30 s past it; a training on 2 H200s to its end): `kill`, `timeout`, Slurm's scancel and `docker
    stop` stop a run with SIGTERM. Each joined process now ends on it at once."""
    import signal
    import time

    port = _free_port()
    long = ("--seeds", "4000", "--steps", "2000")  # minutes of work: still running when signalled
    procs = [_start(1, tmp_path / "out", port, *long), _start(0, tmp_path / "out", port, *long)]
    try:
        t = time.monotonic()
        while not (tmp_path / "out" / ".parts").exists() and time.monotonic() - t < 120:
            assert all(p.poll() is None for p in procs), [p.communicate() for p in procs]
            time.sleep(0.2)
        assert (tmp_path / "out" / ".parts").exists()  # both joined (process 0 made the folder after agreeing)
        for p in procs:
            p.send_signal(signal.SIGTERM)
            out, err = p.communicate(timeout=20)  # read while it ends: a full pipe never holds it
            assert p.returncode == 128 + signal.SIGTERM, (p.returncode, out[-1000:], err[-2000:])  # 143, as a shell says
    finally:
        for p in procs:
            p.kill()
            p.communicate()
