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


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write to a temporary sibling, then rename over `path`: readers see the old file or the new one."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.fchmod(fd, 0o666 & ~_umask())  # mkstemp makes 0600; results should read like any file written
        with os.fdopen(fd, "wb") as f:
            f.write(data)
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


# What a folder's finished results are, by the file each command writes last.
RESULTS = {"per_seed.parquet": "sweep", "per_episode.parquet": "eval", "metrics.json": "scene",
           "compare.json": "compare", "compare_episodes.json": "compare", "policy.msgpack": "train"}
RUN_FILE = ".run.json"  # which command, and which seeds and settings, the folder's results are from
_HELD: dict[Path, object] = {}  # folders this process has locked, and their open lock files


def claim_out_dir(path: Path, command: str, fingerprint: dict, *, replace: bool = False) -> Path:
    """Make `path` this run's folder: writable, locked against a second run, and holding no finished
    results of another command or of other seeds or settings unless `replace` says to drop them.

    One folder holds one run: a sweep into a finished eval folder would replace its summary.json
    and leave its table without one, and a rerun with other seeds would overwrite a finished table.
    A rerun of the same command with the same seeds and settings may overwrite its own results."""
    import hashlib

    path = prepare_out_dir(path)
    _lock(path)
    mine = {"command": command,
            "fingerprint": hashlib.sha256(json.dumps(fingerprint, sort_keys=True, default=str).encode()).hexdigest()}
    # a summary.json counts too: every command writes one, and one with no run file beside it is no run's here
    held = [name for name in (*RESULTS, "summary.json") if (path / name).exists()]
    if held:
        try:
            owner = json.loads((path / RUN_FILE).read_text())
        except (OSError, ValueError):
            # results from before this file existed are known by their name; a lone summary.json by nobody
            owner = {"command": RESULTS.get(held[0], "not mjx-pusht")}
        same = owner.get("command") == command and owner.get("fingerprint", mine["fingerprint"]) == mine["fingerprint"]
        if not same and not replace:
            what = ("another command's" if owner.get("command") != command else "other seeds' or settings'")
            raise OutputError(f"--out {path} holds {what} finished results ({owner.get('command')}: {', '.join(held)}); "
                              "pass --replace to overwrite them, or choose another --out")
        if not same:
            for f in [*(path / name for name in held), *path.glob("*.rrd")]:
                f.unlink(missing_ok=True)
            print(f"--replace: removed the earlier {owner.get('command')} results in {path} ({', '.join(held)})")
    atomic_write_json(path / RUN_FILE, mine)
    return path


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
