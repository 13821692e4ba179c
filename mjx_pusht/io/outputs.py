"""Output folders and files: checked before anything runs, written atomically so none is half-written."""

from __future__ import annotations

import json
import os
import tempfile
import threading
from pathlib import Path

from mjx_pusht.errors import MjxPushtError
from mjx_pusht.io.own import BOOKKEEPING, INSIDE, OWN, PROBE, RESULTS, RUN_FILE, owns, remove_own, runs_holding
from mjx_pusht.io.replace import ASIDE, remember_run_file, set_aside, settle


class OutputError(MjxPushtError, OSError):
    """--out cannot hold the run's files; the message says why."""


def prepare_out_dir(path: Path) -> Path:
    """Create `path` if needed and prove it is a writable folder, before any work is done."""
    if not str(path).strip():  # Path('') is the current folder, which a run would write into
        raise OutputError("--out is empty: give a folder, such as outputs/run")
    path = Path(path)
    try:  # a symlink to itself (a loop) or to nothing: mkdir would fail on it, resolve() raise RuntimeError
        if os.path.islink(path) and not os.path.exists(path):
            raise OutputError(f"--out {path} is a symlink to nothing (or a loop): give a folder")
        if path.resolve() == Path(path.resolve().anchor):  # --share-out would write a run's files among the system's
            raise OutputError(f"--out {path} is the filesystem's root: give a folder of the run's own, such as "
                              "outputs/run")
    except RuntimeError as e:
        raise OutputError(f"--out {path}: {e}") from None
    try:
        if path.exists() and not path.is_dir():
            raise OutputError(f"--out {path} is a file, not a folder")
        if not path.exists():  # it, and the folders above it this run makes, innermost first
            _CREATED[path.resolve()] = [p.resolve() for p in path.parents if not p.exists()]
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-"):
            pass
    except OutputError:
        raise
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


class BackgroundWrite(threading.Thread):
    """A write on a thread of its own (a checkpoint while training goes on). Its failure (a full disk) is raised
    where it is joined, not only printed; an interrupted command waits for it (`finish_background_writes`)."""

    running: set[BackgroundWrite] = set()

    def __init__(self, write, name: str):
        super().__init__(name=name)
        self.write, self.error = write, None

    def start(self) -> None:
        BackgroundWrite.running.add(self)
        super().start()

    def run(self) -> None:
        try:
            self.write()
        except BaseException as e:  # noqa: BLE001 - handed to the joining thread as it is
            self.error = e
        finally:
            BackgroundWrite.running.discard(self)

    def join(self, timeout=None) -> None:
        super().join(timeout)
        if self.error is not None:
            raise self.error


def finish_background_writes() -> None:
    """Wait for every `BackgroundWrite` still running (their failures are theirs to report, not raised here)."""
    for w in list(BackgroundWrite.running):
        threading.Thread.join(w)


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

    sink = pa.BufferOutputStream()
    pq.write_table(pa.table(columns), sink)
    atomic_write_bytes(path, sink.getvalue().to_pybytes())


def read_table(path: Path) -> dict:
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    return {name: table.column(name).to_numpy() for name in table.column_names}


_HELD: dict[Path, int] = {}  # folders this process has locked, and the descriptors holding their locks
_CREATED: dict[Path, list] = {}  # --out folders this process made, and the folders it made above them
_CLAIMS: dict[Path, str] = {}  # folders whose run file this process wrote where there was none, and its command


def claim_out_dir(path: Path, command: str, fingerprint: dict, *, replace: bool = False, reads=(),
                  share: bool = False, check=None, writes=(), earlier=()) -> Path:
    """Make `path` this run's folder: writable, locked against a second run, and holding no results of another
    command, nor of this command with other seeds or settings unless `replace` says to drop those, nor files
    no run of this command wrote unless `share` says to write beside them.

    One folder holds one run. Another command's results (an eval's table, a train's policy) are refused
    whatever the flags: `--replace` removes only this command's own files (`OWN`, `INSIDE`), and never a file the
    run reads (`reads`: the policy it evaluates, the evals it compares). A rerun of the same command with the same
    seeds and settings may overwrite its own results. A name this command writes (demos' data/, sweep's .parts)
    that holds a file it did not write is refused whatever the flags: writing there would mix or remove it.

    `writes`: files the run writes in `path` besides its own names (eval's --video, checked by its own rule: a
    file there is an earlier eval's of this folder), not strays. `earlier`: files in `path` an earlier run of this
    command wrote besides its own names (the video an eval drew inside its --out, by its summary's stamp): not
    strays, and set aside with the results under --replace. `check(path, same)`: the command's own refusals (`same`: the folder's run file is this command's, with these
    seeds and settings), run after these and before the run file is written: a refused run changes nothing."""
    import hashlib

    path = prepare_out_dir(path)
    _lock(path)
    _refuse_another_runs_folder(path, command)
    mine = {"command": command,
            "fingerprint": hashlib.sha256(json.dumps(fingerprint, sort_keys=True, default=str).encode()).hexdigest()}
    held, owner = _owner(path)
    who = owner.get("command")
    if held or who not in (None, command):  # a run file alone is a run too: `sweep --share-out` rewrote demos'
        foreign = (held or [RUN_FILE]) if who != command else [n for n in held if n not in OWN[command]]
        if foreign:
            what = (f"{who}'s results" if who in OWN else f"results whose {RUN_FILE} is unreadable"
                    if (path / RUN_FILE).exists() else "files no mjx-pusht run wrote here") if who != command \
                else f"files {command} does not write"
            raise OutputError(f"--out {path} holds {what} ({', '.join(foreign)}); {command} never removes or "
                              "overwrites another command's results, whatever the flags: choose another --out")
    strays = [s for s in stray_files(path, command)
              if (path / s).resolve() not in {Path(w).resolve() for w in (*writes, *earlier)}]
    # this command's names, not written by a run of it here (no run file of its own): a user's data/, .parts, eval/
    taken = [n for n in OWN[command] if who != command and (os.path.lexists(path / n))]
    mixed = taken + [s for s in strays if s.split("/")[0] in OWN[command] and s.split("/")[0] not in taken]
    if mixed:
        raise OutputError(f"--out {path} holds {_listed(mixed)}, which {command} writes but no {command} run wrote "
                          f"here; {command} never removes or mixes into them, whatever the flags: choose another --out")
    if strays and not share:
        raise OutputError(f"--out {path} holds files {command} did not write ({_listed(strays)}); {command} never "
                          "removes them: pass --share-out to write its files beside them, or choose another --out")
    other = held and owner.get("fingerprint", mine["fingerprint"]) != mine["fingerprint"]
    if other and not replace:
        raise OutputError(f"--out {path} holds other seeds' or settings' finished results ({command}: "
                          f"{', '.join(held)}); pass --replace to overwrite them, or choose another --out")
    _refuse_to_remove_inputs(path, command, reads)  # this run writes over its own files: none may be an input
    if check is not None:  # before --replace removes anything and before the run file: a refused run changes nothing
        check(path, who == command and owner.get("fingerprint") == mine["fingerprint"])
    if other:  # set aside, not removed, until this run finishes (replace.py): a failed run puts them back
        set_aside(path, command, also=[rel for rel in (Path(e).resolve().relative_to(path.resolve()) for e in earlier)
                                       if rel.parts[0] != ASIDE])
        print(f"--replace: the earlier {command} results in {path} ({', '.join(held)}) are set aside until this run "
              "finishes")
    if not (path / RUN_FILE).exists():
        _CLAIMS[path.resolve()] = command
    remember_run_file(path, command)
    atomic_write_json(path / RUN_FILE, mine)
    return path


def _owner(path: Path) -> tuple[list[str], dict]:
    """The results `path` holds, and its run file (or, without one, the command those results are of)."""
    held = _results_in(path)
    try:
        owner = json.loads((path / RUN_FILE).read_text())
        if not isinstance(owner, dict):
            raise ValueError(RUN_FILE)
    except (OSError, ValueError):
        # chunks are known by their manifest (whose seeds and settings the resume check compares); results with
        # no run file by nobody: a user's lone per_episode.parquet was taken for an eval's and overwritten (the
        # eleventh pass), so it is refused as files no run wrote
        owner = {"command": _chunks_command(path)}
    return held, owner


def _refuse_another_runs_folder(path: Path, command: str) -> None:
    """Refuse `path` when it lies inside another run's folder, at any depth (a train's eval/, whose results the
    train wrote as its judgement; a new folder under a finished eval's): --replace there would remove that run's
    files, and a new run's files there are strays in it. The run that holds a folder above (train judging its
    policy) may. A run is known by its run file (a folder merely holding a policy file is a user's, and its eval/
    theirs to write; benchmarks' folders of runs, like train_scaling's OUT/devices-N, have none)."""
    here = path.resolve()
    for above, who in runs_holding(here.parent):
        if above in _HELD:
            return
        raise OutputError(f"--out {path} is inside the {who} run in {above} (its {here.relative_to(above).parts[0]}/); "
                          f"{command} never writes into another run's folder, whatever the flags: choose another --out")


def _listed(names: list[str], most: int = 6) -> str:
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def stray_files(path: Path, command: str) -> list[str]:
    """What `path` holds that `command` never writes: files and folders by their path inside it (a folder that is
    not one of the command's is named whole, with a trailing /, and not looked into). Inside `.replaced/` (--replace's
    earlier results, replace.py) the same: a user's file there is a stray, as anywhere else."""
    patterns = (*BOOKKEEPING, PROBE, *(n for n in OWN[command] if n not in INSIDE),
                *(f"{n}/{p}" for n in OWN[command] if n in INSIDE for p in INSIDE[n]))
    strays = []
    for root, dirs, files in os.walk(path):
        rel = Path(root).relative_to(path)
        inner = Path(*rel.parts[1:]) if rel.parts[:1] == (ASIDE,) else rel  # the same names, set aside
        for d in list(dirs):
            if rel == Path(".") and d == ASIDE and not os.path.islink(path / d):
                continue
            if os.path.islink(Path(root) / d) or (inner == Path(".") and d not in OWN[command]):
                dirs.remove(d)
                strays.append((rel / d).as_posix() + "/")
        strays += [(rel / f).as_posix() for f in files if not owns((inner / f).as_posix(), patterns)]
    return sorted(strays)


def _results_in(path: Path) -> list[str]:
    """The results a folder holds, by name: finished files, unfinished chunks, a training run's checkpoints.
    (A train's eval/ folder is its own; an eval/ beside other results is not taken for one, as outputs/eval; a
    dataset's data/ and meta/ are demos' only beside its run file, which write_demos checks.)"""
    held = []
    for name in sorted({*RESULTS, *(n for own in OWN.values() for n in own)} - {"eval", *OWN["demos"]}):
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


def _lock(path: Path) -> None:
    """Hold an exclusive lock on `path` until `held_folders` lets go (or this process ends): a second run into the
    same folder stops in one line instead of racing this one for its chunk files. The lock is the kernel's, on the
    folder itself (flock on its descriptor): no lock file is written, so a refused run leaves none, and a killed
    run's lock goes with its process."""
    import fcntl

    key = path.resolve()
    if key in _HELD:
        return
    fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise OutputError(f"--out {path} is in use by another mjx-pusht run; wait for it to finish "
                          "or choose another --out") from None
    _HELD[key] = fd


class held_folders:
    """`with held_folders():` around a command: the folders it locked are let go when it ends (a command
    run inside another, as train runs eval, lets go of its own only). A command that failed (bad input found
    after its claim, as a backend refusing the task) leaves no folder it made that holds only its claim."""

    def __enter__(self):
        self.before, self.failed = set(_HELD), False  # failed: a command that answered non-zero (an interrupt's 130)
        return self

    def __exit__(self, kind, exc, tb):
        for key in set(_HELD) - self.before:
            os.close(_HELD.pop(key))
            settle(key, exc is None and not self.failed)
            command, parts = _CLAIMS.pop(key, None), key / ".parts"
            if exc is None and not self.failed:
                continue
            if parts.is_dir() and not parts.is_symlink() and not any(parts.glob("seeds-*")):
                remove_own(parts)  # a failed batch's manifest with no chunk finished: nothing to resume, no trace
            if command and not any(os.path.lexists(key / n) for n in OWN[command]):
                (key / RUN_FILE).unlink(missing_ok=True)  # refused after its claim (a backend's check): no trace
            if key in _CREATED and _only_claim(key):
                for name in os.listdir(key):
                    (key / name).rmdir() if (key / name).is_dir() else (key / name).unlink()
                for folder in (key, *_CREATED[key]):
                    if os.listdir(folder):
                        break
                    folder.rmdir()


def _only_claim(path: Path) -> bool:
    """`path` holds nothing but a claim: the bookkeeping files, and folders a run made and left empty."""
    return all(n in BOOKKEEPING or ((path / n).is_dir() and not (path / n).is_symlink() and not os.listdir(path / n))
               for n in os.listdir(path))
