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
