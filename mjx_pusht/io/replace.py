"""`--replace`: the earlier results of a folder are set aside, not removed, until the run that replaces them
finishes. A run that fails (a controller that raises, a NaN, a backend's refusal found after the claim) or is
interrupted before it kept anything to resume puts them back as they were; one that kept something to resume
(an eval's or a sweep's finished chunks, a train's checkpoint) leaves them aside in `.replaced/` until a run
into the folder finishes. So `--replace` never loses a finished result to a run that did not finish (a tenth
hostile pass: an eval with `--replace` whose controller raised left only its run file).

What is set aside is exactly what `remove_own` would remove: the command's own files by name, and inside its
folders the files it writes there; a user's file inside one of them stays where it is."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from mjx_pusht.io.own import INSIDE, OWN, RUN_FILE, owns, remove_own

ASIDE = ".replaced"  # inside --out: the earlier results, laid out as they were
_PENDING: dict[Path, str] = {}  # folders whose results this process set aside, and the command
_RUN_FILES: dict[Path, bytes] = {}  # the run file a claim wrote over: a run that fails puts it back
_COMMANDS: dict[Path, str] = {}  # the command each folder this process claimed is for
_ALSO: dict[Path, list] = {}  # files besides the command's own names set aside with its results (eval's video)


def remember_run_file(path: Path, command: str) -> None:
    """Keep the run file `path` holds before a claim writes its own: a run that fails with nothing to resume puts
    it back, so a folder's earlier results (demos' dataset, kept by demos itself) stay described by their own
    seeds and settings, not by the failed run's."""
    _COMMANDS[path.resolve()] = command
    if (path / RUN_FILE).is_file() and not (path / RUN_FILE).is_symlink():
        _RUN_FILES[path.resolve()] = (path / RUN_FILE).read_bytes()


def _own_files(p: Path, patterns) -> list[Path]:
    """The files under `p` (a command's own file or folder) that it writes: what remove_own removes."""
    if p.is_symlink() or not p.is_dir():
        return [p] if os.path.lexists(p) else []
    return [Path(root) / f for root, _, files in os.walk(p) for f in files
            if owns((Path(root).relative_to(p) / f).as_posix(), patterns)]


def set_aside(path: Path, command: str, also=()) -> None:
    """Move the command's earlier results in `path` (and its run file, copied) into `path/.replaced`, with `also`
    (paths inside `path` an earlier run of it wrote besides its own names: an eval's video inside its --out). A
    `.replaced` already there (left by an interrupted replacement) keeps the older finished results, and the
    unfinished ones now in the folder are removed, as --replace says."""
    aside = path / ASIDE
    _PENDING[path.resolve()] = command
    _ALSO[path.resolve()] = [Path(a) for a in also if not (aside / a).exists()]
    for rel in _ALSO[path.resolve()]:
        (aside / rel).parent.mkdir(parents=True, exist_ok=True)
        os.rename(path / rel, aside / rel)
    if aside.is_dir() and any(_own_files(aside / n, INSIDE.get(n, ())) for n in OWN[command]):
        for name in OWN[command]:
            remove_own(path / name)
        return
    aside.mkdir(exist_ok=True)  # (a user's file in one is theirs: the claim let it be only with --share-out)
    if (path / RUN_FILE).is_file():
        shutil.copy2(path / RUN_FILE, aside / RUN_FILE)
    for name in OWN[command]:
        for f in _own_files(path / name, INSIDE.get(name, ())):
            rel = f.relative_to(path)
            (aside / rel).parent.mkdir(parents=True, exist_ok=True)
            os.rename(f, aside / rel)
        remove_own(path / name)  # the folders the move left empty


def _resumable(path: Path) -> bool:
    return any((path / ".parts").glob("seeds-*.parquet")) or (path / "checkpoints" / "resume.msgpack").is_file()


def settle(key: Path, ok: bool) -> None:
    """When the command that claimed `key` ends: finished (`ok`), the earlier results set aside go; failed with
    nothing to resume, they come back and this run's own files go; failed with something to resume, they wait."""
    command, earlier, also = _PENDING.pop(key, None), _RUN_FILES.pop(key, None), _ALSO.pop(key, [])
    if not ok and earlier is not None and not _resumable(key) and (key / RUN_FILE).is_file():
        (key / f"{RUN_FILE}.restore").write_bytes(earlier)
        os.replace(key / f"{RUN_FILE}.restore", key / RUN_FILE)  # (one set aside comes back whole below)
    aside = key / ASIDE
    if not aside.is_dir() or aside.is_symlink():
        return
    owner = _COMMANDS.pop(key, command)
    if ok and owner:  # this run, or a resumed one, finished: what it replaced goes (left by an interrupted one too)
        _discard(aside, owner, also)
        return
    if command is None:  # a run that replaced nothing, failed: what an earlier one set aside keeps waiting
        return
    if _resumable(key):
        print(f"--replace: the earlier results wait in {aside} until a run here finishes")
        return
    for name in OWN[command]:
        remove_own(key / name)
    for name in (*OWN[command], RUN_FILE):  # only what a run of it wrote: a user's file there stays put
        for f in _own_files(aside / name, INSIDE.get(name, ())):
            rel = f.relative_to(aside)
            (key / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(f, key / rel)
    for rel in also:
        if os.path.lexists(aside / rel) and not os.path.lexists(key / rel):
            os.replace(aside / rel, key / rel)
    _discard(aside, command, also)
    print(f"--replace: this run did not finish: the earlier results in {key} are back as they were; this run's are "
          "removed")


def _discard(aside: Path, command: str, also=()) -> None:
    """Remove what `.replaced/` holds of `command`'s (and its run file, and the `also` files set aside with it), and
    the folder if that empties it: a user's file there stays (the eleventh pass: a finishing --replace deleted the
    whole folder)."""
    for name in OWN[command]:
        remove_own(aside / name)
    for rel in also:
        (aside / rel).unlink(missing_ok=True)
    (aside / RUN_FILE).unlink(missing_ok=True)
    try:
        aside.rmdir()
    except OSError:
        pass
