"""The command line's boundary, fuzzed: `mjx_pusht.cli.main([...])` in this process, its flags given odd values and
its --out (and eval's --video) pointed at folders a user or another run owns (tests/fuzzing.py: budget, values).

The property, per try: either exit 0, every file that existed before unchanged, anything new inside the run's own
fresh --out (or its fresh --video); or a refusal, exit 1 or 2 and one stderr line `mjx-pusht: error: ...`, and
nothing outside the run's own fresh --out added, changed or removed (no `.lock`, no folder, no probe; inside it, a
run that failed once running keeps what --resume needs). The cheap commands run for real (CPU
backend, a few steps); `train`'s and `compare`'s doors are the same claim_out_dir (tests/test_refused_writes_nothing.py
covers them), and the multi-process flags are fuzzed through `Processes` in test_fuzz_api.py (a valid pair here would
wait for a peer). Each `@example` is a case a hostile pass found.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import json
import os
import sys

import pytest
from hypothesis import event, example, given
from hypothesis import strategies as st

from fuzzing import FUZZ, snapshot
from helpers import without
from mjx_pusht.cli import main

BASE = {
    "scene": ["scene", "--no-rerun", "--steps", "50"],
    "tree": ["tree"],
    "sweep": ["sweep", "--backend", "cpu", "--seeds", "2", "--steps", "5", "--no-rerun", "--no-progress"],
    "eval": ["eval", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-rerun", "--no-progress"],
    "demos": ["demos", "--backend", "cpu", "--seeds", "2", "--max-steps", "3", "--no-progress"],
}
FLAGS = {  # the flags fuzzed (not the MJX backends, nor --audit: each compiles MJX)
    "scene": ["--seed", "--steps", "--break", "--compare-welded", "--replace", "--share-out"],
    "tree": ["--break", "--pusher", "--json", "--colliders"],
    "sweep": ["--seeds", "--backend", "--break", "--chunk", "--resume", "--replace", "--share-out", "--record",
              "--param", "--randomize", "--steps", "--process-id", "--coordinator", "--peer-timeout"],
    "eval": ["--seeds", "--backend", "--break", "--chunk", "--resume", "--replace", "--share-out", "--param",
             "--randomize", "--controller", "--action", "--task", "--reset", "--goal", "--success-threshold",
             "--max-steps", "--frame-skip", "--video-episodes", "--video-size"],
    "demos": ["--seeds", "--controller", "--task", "--successful-only", "--action", "--batch", "--max-steps",
              "--success-threshold", "--replace", "--share-out"],
}
SWITCHES = {"--compare-welded", "--replace", "--share-out", "--json", "--colliders", "--resume", "--successful-only"}
VALUES = st.one_of(
    st.sampled_from(["-1", "0", "1", "2", "1e3", "nan", "inf", "-inf", "", " ", "٣", "１", "0x10", "+2", "9" * 25,
                     "1,1", "2:1", "0:3", "kv=nan", "kv=10,20", "tee_mass=0.5:2:2", "kv=0.5:1.5", "bogus=1", "cpu",
                     "gym-pusht", "none", "split-tee", "capsule", "expert", "zero", "random", "policy:/nonexistent",
                     "os:getcwd", "velocity", "target", "task", "easy", "fixed", "0.5", "1.5", "127.0.0.1:12345",
                     "127.0.0.1:99999", "host with space:1", "\u202e", "a\nb"]),
    st.text(max_size=8), st.integers(-10, 10).map(str))
GOOD = {  # a valid value per flag, drawn half the time, so that tries get past the parser into the runs
    "--seeds": ["1", "3", "0:2", "5,7"], "--steps": ["3", "10"], "--seed": ["0", "7"], "--chunk": ["1", "2"],
    "--break": ["none", "split-tee", "free-tee"], "--pusher": ["cylinder", "capsule"], "--record": ["0", "1"],
    "--param": ["kv=10,20", "tee_mass=0.5"], "--randomize": ["kv=0.5:1.5", "tee_mass=0.8:1.2"],
    "--controller": ["expert", "zero", "random", *(f"ctl_fuzz:{n}" for n in (
        "nan", "inf_later", "neg_inf_one_row", "shape", "none", "text", "raises", "ints", "huge", "as_list",
        "not_callable", "missing", "osexit", "cplx", "boolean"))], "--action": ["velocity", "position", "target"],
    "--task": ["chapter", "gym-pusht", "gym-pusht-easy"], "--reset": ["task", "easy", "chapter"],
    "--goal": ["fixed", "random"], "--success-threshold": ["0.9", "0.5"], "--max-steps": ["2", "4"],
    "--frame-skip": ["5", "10"], "--video-episodes": ["1", "2"], "--video-size": ["32", "48"], "--batch": ["1", "2"],
    "--backend": ["cpu", "gym-pusht"], "--process-id": ["0"], "--coordinator": ["127.0.0.1:12345"],
    "--peer-timeout": ["1"]}
OUTS = st.sampled_from(["fresh", "users", "link", "loop", "file", "root", "empty", "train", "train/eval",
                        "train/checkpoints", "finished"])
VIDEOS = st.sampled_from([None, "fresh.gif", "users/picture.gif", "fresh.avi", "users", "link/new.gif", "train/v.gif"])
_count = itertools.count()


# A user's controllers (`--controller ctl_fuzz:NAME`), each handing back something a controller should not
CONTROLLERS = """
import numpy as np
def nan(obs, t): return np.full(obs["state"].shape[:-1] + (2,), np.nan)
def inf_later(obs, t): return np.full(obs["state"].shape[:-1] + (2,), np.inf if t >= 2 else 0.0)
def neg_inf_one_row(obs, t):
    a = np.zeros(obs["state"].shape[:-1] + (2,)); a[..., -1:, 0] = -np.inf; return a
def shape(obs, t): return np.zeros(3)
def none(obs, t): return None
def text(obs, t): return np.full(obs["state"].shape[:-1] + (2,), "a")
def raises(obs, t): raise ZeroDivisionError("boom")
def ints(obs, t): return np.zeros(obs["state"].shape[:-1] + (2,), int)
def huge(obs, t): return np.full(obs["state"].shape[:-1] + (2,), 1e300)
def as_list(obs, t): return [[0.0, 0.0]] * len(obs["state"])
def osexit(obs, t):
    import os; os._exit(0)
def cplx(obs, t): return np.zeros(obs["state"].shape[:-1] + (2,), complex)
def boolean(obs, t): return np.ones(obs["state"].shape[:-1] + (2,), bool)
not_callable = 3
"""


@pytest.fixture(scope="module")
def worlds(tmp_path_factory):
    root = tmp_path_factory.mktemp("worlds")
    (root / "ctl_fuzz.py").write_text(CONTROLLERS)
    sys.path.insert(0, str(root))
    for command in BASE:  # a finished run of each command, copied into each try's world as its "finished" --out
        if command != "tree":
            with contextlib.redirect_stdout(io.StringIO()):
                assert main([*BASE[command], "--out", str(root / f"finished-{command}")]) == 0
    yield root
    sys.path.remove(str(root))


def _world(root, command: str):
    """A user's folder (and a symlink to it, a loop, a file), a train run's folder with its own eval/, and a finished
    run of `command`: made afresh for every try, so that one try's files are never the next one's."""
    import shutil

    if command != "tree":
        shutil.copytree(root.parent / f"finished-{command}", root / "finished", symlinks=True)
    users = root / "users"
    (users / "data").mkdir(parents=True)
    (users / "notes.md").write_text("mine")
    (users / "data" / "mine.csv").write_text("1,2\n")
    (users / "picture.gif").write_bytes(b"GIF89a a user's picture")
    os.symlink(users, root / "link")
    os.symlink(root / "loop", root / "loop")
    (root / "file").write_text("a file")
    train = root / "train"  # as `train` leaves it: its run file, its policy, its own judgement in eval/
    (train / "eval").mkdir(parents=True)
    (train / "checkpoints").mkdir()
    (train / ".run.json").write_text(json.dumps({"command": "train", "fingerprint": "x"}))
    (train / "policy.msgpack").write_bytes(b"weights")
    (train / "checkpoints" / "policy_1.msgpack").write_bytes(b"weights")
    (train / "eval" / ".run.json").write_text(json.dumps({"command": "eval", "fingerprint": "y"}))
    (train / "eval" / "summary.json").write_text("{}")
    (train / "eval" / "per_episode.parquet").write_bytes(b"table")
    return root


def _out(world, kind: str) -> tuple[str, str | None]:
    """The --out argument, and the folder the run would own (a fresh one) or None."""
    if kind == "fresh":
        fresh = str(world / f"runs/r{next(_count)}")
        return fresh, fresh
    return {"root": "/", "empty": ""}.get(kind, str(world / kind)), None


def _try(argv, world, owned: list[str], replaced: list[str], finished: bool = False):
    """`argv` run, and the property checked: `owned` the paths it may add files under, `replaced` those whose
    existing files it may change (a --video named with --replace); `finished`: its --out holds a finished run of
    its command, which only a run that ends with exit 0 may change (a rerun, or --replace: a failed one leaves the
    earlier results as they were)."""
    before = snapshot(world)
    root_before = sorted(os.listdir("/"))
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(argv)
        except SystemExit as e:  # argparse's --help
            code = e.code
    after = snapshot(world)
    event(f"{argv[0]} exit {code}")  # --hypothesis-show-statistics: how many tries ran, how many were refused
    assert sorted(os.listdir("/")) == root_before, "a file was left in /"
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    if code == 0:
        owned, replaced = (owned + ["finished"], replaced + ["finished"]) if finished else (owned, replaced)

        def theirs(p, mine):
            return not any(p == o or p.startswith(o + "/") for o in mine)

        changed = {p for p in before if after.get(p, "gone") != before[p] and theirs(p, replaced)}
        assert not changed, f"{argv}: changed or removed {sorted(changed)[:5]}"
        stray = [p for p in after if p not in before and theirs(p, owned)]
        assert not stray, f"{argv}: wrote outside what it owns: {stray[:5]}"
        assert "Traceback" not in err.getvalue(), err.getvalue()[-2000:]
    else:
        assert code in (1, 2), (argv, code, err.getvalue()[-2000:])
        assert len(lines) == 1 and lines[0].startswith("mjx-pusht: error: "), (argv, err.getvalue()[-2000:])
        # nothing anywhere, but in the run's own fresh --out: a run that failed once running (a user's controller
        # raising at its first step) keeps what --resume needs there; refusals at the door leave nothing at all
        # (tests/test_refused_writes_nothing.py)
        moved = {p for p in set(before) | set(after) if before.get(p, "new") != after.get(p, "gone")}
        outside = [p for p in moved if not any(p == o or p.startswith(o + "/") for o in owned)]
        assert not outside, f"{argv}: a refused run changed {sorted(outside)[:5]}"


@FUZZ
@given(command=st.sampled_from(sorted(BASE)), data=st.data())
@example(command="scene", data=["--out", "root"])  # each command left /.lock
@example(command="sweep", data=["--out", "link"])  # a .lock among a user's files
@example(command="sweep", data=["--out", "loop"])  # RuntimeError: Symlink loop
@example(command="eval", data=["--replace", "--out", "train/eval"])  # overwrote the train's own judgement
@example(command="eval", data=["--video", "users/picture.gif", "--out", "fresh"])  # overwrote a user's picture
@example(command="eval", data=["--replace", "--video", "users/picture.gif", "--out", "fresh"])  # overwrote it too
@example(command="sweep", data=["--coordinator", "127.0.0.1:12345", "--out", "fresh"])  # ran alone, or hung
@example(command="sweep", data=["--coordinator", "127.0.0.1:99999", "--out", "fresh"])  # OverflowError
@example(command="eval", data=["--controller", "ctl_fuzz:raises", "--out", "fresh"])  # a user's controller failing
@example(command="eval", data=["--controller", "ctl_fuzz:inf_later", "--out", "fresh"])
@example(command="sweep", data=["--share-out", "--backend", "gym-pusht", "--out", "users"])  # found: left .run.json
@example(command="sweep", data=["--share-out", "--out", "root"])  # found: wrote its table into / (as root)
@example(command="demos", data=["--success-threshold", "\r0", "--out", "fresh"])  # found: a value's \r made 2 lines
@example(command="eval", data=["--controller", "ctl_fuzz:osexit", "--out", "fresh"])  # a silent exit 0, no table
@example(command="eval", data=["--controller", "ctl_fuzz:cplx", "--out", "fresh"])  # imaginary part dropped
@example(command="eval", data=["--controller", "ctl_fuzz:as_list", "--out", "fresh"])  # refused as "shape None"
@example(command="eval", data=["--replace", "--controller", "ctl_fuzz:raises", "--out", "finished"])  # tenth pass: the
@example(command="sweep", data=["--replace", "--break", "bogus", "--out", "finished"])  # earlier results were lost
@example(command="demos", data=["--replace", "--controller", "ctl_fuzz:nan", "--out", "finished"])
def test_every_command_keeps_the_property(command, data, worlds):
    world = _world(worlds / f"w{next(_count)}", command)
    os.chdir(world)  # an --out of "" would write here
    if isinstance(data, list):  # an @example: flags as given, with --out's and --video's kinds
        flags, kinds = data, {}
        for i, a in enumerate(flags):
            if flags[i - 1] in ("--out", "--video") and i:
                kinds[i] = a
    else:
        chosen = data.draw(st.lists(st.sampled_from(FLAGS[command]), max_size=3, unique=True))
        if chosen and data.draw(st.integers(0, 9)) == 0:  # now and then a flag given twice: refused, never the last
            chosen.append(chosen[0])  # value taken over the first (the thirteenth pass)
        flags = [x for f in chosen for x in ([f] if f in SWITCHES else
                                             [f, data.draw(st.one_of(st.sampled_from(GOOD[f]), VALUES))])]
        kinds = {}
        if command != "tree":
            flags += ["--out", data.draw(OUTS)]
            kinds[len(flags) - 1] = flags[-1]
        if command == "eval":
            video = data.draw(VIDEOS)
            if video is not None:
                flags += ["--video", video, "--video-size", "32"]
                kinds[len(flags) - 3] = video
    # a drawn flag in place of the base's own (each flag is taken once)
    owned, replaced, argv = [], [], [BASE[command][0], *without(BASE[command][1:], set(flags))]
    for i, a in enumerate(flags):
        if i in kinds and flags[i - 1] == "--out":
            a, fresh = _out(world, a)
            owned += [os.path.relpath(fresh, world), "runs"] if fresh else []
            if "--share-out" in flags and a not in ("", "/"):  # documented: its files beside the folder's own
                owned.append(os.path.relpath(os.path.realpath(a), world))
        elif i in kinds:  # --video: a new file is the run's; an existing one no run of this --out wrote is never
            if not os.path.lexists(world / a):  # changed, --replace or not (the fuzz world's files are no video's)
                owned.append(os.path.relpath(os.path.realpath(world / a), world))
            a = str(world / a)
        argv.append(a)
    _try(argv, world, owned, replaced, finished=any(kinds.get(i) == "finished" for i in kinds))
