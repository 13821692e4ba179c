"""Output folders and files: checked before anything runs, written atomically so none is half-written."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from mjx_pusht.errors import MjxPushtError


class OutputError(MjxPushtError, OSError):
    """--out cannot hold the run's files; the message says why."""


def prepare_out_dir(path: Path) -> Path:
    """Create `path` if needed and prove it is a writable folder, before any work is done."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"--out {path} is a file, not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-"):
            pass
    except OSError as e:
        raise OutputError(f"--out {path} is not writable: {e.strerror or e}") from None
    return path


def atomic_write_bytes(path: Path, *data) -> None:
    """Write `data` (bytes, or several buffers one after another, e.g. numpy arrays: written from their memory as it
    is, with the GIL released while they go out) to a temporary sibling, then rename over `path`: readers see the old
    file or the new one."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; results should read like any file written
        with os.fdopen(fd, "wb") as f:
            for part in data:
                f.write(memoryview(part).cast("B"))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def drop_stale(path: Path) -> None:
    """Remove an output of an earlier run that this run replaces but does not rewrite (a recording)."""
    if path.exists():
        path.unlink()
        print(f"removed {path}: it recorded an earlier run, and this run was not recorded")


def atomic_write_json(path: Path, obj) -> None:
    atomic_write_bytes(path, (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode())


def atomic_write_table(path: Path, columns: dict) -> None:
    """A parquet table from named NumPy columns, written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table(columns)
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    atomic_write_bytes(path, sink.getvalue().to_pybytes())


def read_table(path: Path) -> dict:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    return {name: table.column(name).to_numpy() for name in table.column_names}


# What a folder's finished results are, by the file each command writes last (a folder from before the run
# file existed is known by these names).
RESULTS = {"per_seed.parquet": "sweep", "per_episode.parquet": "eval", "metrics.json": "scene",
           "compare.json": "compare", "compare_episodes.json": "compare", "policy.msgpack": "train"}
# Everything each command writes in its --out: what --replace may remove, and never anything else. A rerun
# of the same command replaces its own results; another command's results are never touched.
OWN = {
    "sweep": ("per_seed.parquet", "summary.json", "sweep.rrd", "audit_cpu.parquet", ".parts"),
    "eval": ("per_episode.parquet", "summary.json", "eval.rrd", ".parts"),
    "scene": ("metrics.json", "scene.rrd", "walk.rrd"),
    "compare": ("compare.json", "compare.md", "compare.png", "compare_episodes.json", "compare_episodes.md"),
    "train": ("policy.msgpack", "summary.json", "curve.csv", "curve.png", "train.rrd", "checkpoints", "eval"),
}
RUN_FILE = ".run.json"  # which command, and which seeds and settings, the folder's results are from
_HELD: dict[Path, object] = {}  # folders this process has locked, and their open lock files


def claim_out_dir(path: Path, command: str, fingerprint: dict, *, replace: bool = False, reads=()) -> Path:
    """Make `path` this run's folder: writable, locked against a second run, and holding no results of another
    command, nor of this command with other seeds or settings unless `replace` says to drop those.

    One folder holds one run. Another command's results (an eval's table, a train's policy) are refused
    whatever the flags: `--replace` removes only this command's own files (`OWN`), and never a file the run
    reads (`reads`: the policy it evaluates, the evals it compares). A rerun of the same command with the same
    seeds and settings may overwrite its own results."""
    import hashlib

    path = prepare_out_dir(path)
    _lock(path)
    mine = {"command": command,
            "fingerprint": hashlib.sha256(json.dumps(fingerprint, sort_keys=True, default=str).encode()).hexdigest()}
    held = _results_in(path)
    if held:
        try:
            owner = json.loads((path / RUN_FILE).read_text())
            if not isinstance(owner, dict):
                raise ValueError(RUN_FILE)
        except (OSError, ValueError):
            # results from before the run file existed are known by their name, chunks by their manifest (whose
            # seeds and settings the resume check compares); a lone summary.json by nobody
            owner = {"command": next((RESULTS[n] for n in held if n in RESULTS), None) or _chunks_command(path)}
        who = owner.get("command")
        foreign = held if who != command else [n for n in held if n not in OWN[command]]  # a policy in an eval's folder
        if foreign:
            what = (f"{who}'s results" if who in OWN else f"results whose {RUN_FILE} is unreadable"
                    if (path / RUN_FILE).exists() else "files no mjx-pusht run wrote here") if who != command \
                else f"files {command} does not write"
            raise OutputError(f"--out {path} holds {what} ({', '.join(foreign)}); {command} never removes or "
                              "overwrites another command's results, whatever the flags: choose another --out")
        if owner.get("fingerprint", mine["fingerprint"]) != mine["fingerprint"]:
            if not replace:
                raise OutputError(f"--out {path} holds other seeds' or settings' finished results ({command}: "
                                  f"{', '.join(held)}); pass --replace to overwrite them, or choose another --out")
            _refuse_to_remove_inputs(path, command, reads)
            for name in OWN[command]:
                _remove(path / name)
            print(f"--replace: removed the earlier {command} results in {path} ({', '.join(held)})")
    _refuse_to_remove_inputs(path, command, reads)  # this run writes over its own files: none may be an input
    atomic_write_json(path / RUN_FILE, mine)
    return path


def _results_in(path: Path) -> list[str]:
    """The results a folder holds, by name: finished files, unfinished chunks, a training run's checkpoints.
    (A train's eval/ folder is its own; an eval/ beside other results is not taken for one, as outputs/eval.)"""
    held = []
    for name in sorted({*RESULTS, *(n for own in OWN.values() for n in own)} - {"eval"}):
        p = path / name
        if name == ".parts":
            if any(p.glob("seeds-*.parquet")):
                held.append(name)
        elif name == "checkpoints":
            if p.is_dir() and any(p.iterdir()):
                held.append(name)
        elif p.exists():
            held.append(name)
    return held


def _chunks_command(path: Path) -> str | None:
    """The command whose unfinished chunks `path/.parts` holds, by the manifest run_sweep writes (an eval's config
    names its command; a sweep's is the other); None without a readable one."""
    try:
        manifest = json.loads((path / ".parts" / "manifest.json").read_text())
        return manifest["config"].get("command", "sweep")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


def _refuse_to_remove_inputs(path: Path, command: str, reads) -> None:
    """Refuse a run whose own files in `path` (removed by --replace, or written over) include a file it reads."""
    own = [(path / name).resolve() for name in OWN.get(command, ())]
    for r in reads:
        r = Path(r).resolve()
        for o in own:
            if r == o or o in r.parents:
                raise OutputError(f"--out {path}: this {command} reads {r}, which its own results would replace; "
                                  "choose another --out")


def _remove(p: Path) -> None:
    import shutil

    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    else:
        p.unlink(missing_ok=True)


def _lock(path: Path) -> None:
    """Hold an exclusive lock on `path` until `release` (or this process's end): a second run into the
    same folder stops in one line instead of racing this one for its chunk files."""
    import fcntl

    key = path.resolve()
    if key in _HELD:
        return
    f = open(path / ".lock", "a+")  # noqa: SIM115 - held open for the run's length
    try:
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.seek(0)
        pid = f.read().strip() or "?"
        f.close()
        raise OutputError(f"--out {path} is in use by another mjx-pusht run (pid {pid}); wait for it to finish "
                          "or choose another --out") from None
    f.truncate(0)
    f.write(str(os.getpid()))
    f.flush()
    _HELD[key] = f


class held_folders:
    """`with held_folders():` around a command: the folders it locked are let go when it ends (a command
    run inside another, as train runs eval, lets go of its own only)."""

    def __enter__(self):
        self.before = set(_HELD)

    def __exit__(self, *exc):
        for key in set(_HELD) - self.before:
            _HELD.pop(key).close()
