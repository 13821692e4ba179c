"""What each command owns in its --out: the names it writes there (and inside its folders, the files it puts there),
the results that say a run finished, the run file. `--replace` removes (or sets aside: replace.py) only these; a
file matching none of them is a user's, and no command removes it."""

from __future__ import annotations

import os
from pathlib import Path

# What a folder's finished results are, by the file each command writes last (a folder from before the run
# file existed is known by these names).
RESULTS = {"per_seed.parquet": "sweep", "per_episode.parquet": "eval", "metrics.json": "scene",
           "compare.json": "compare", "compare_episodes.json": "compare", "policy.msgpack": "train"}
RUN_FILE = ".run.json"  # which command, and which seeds and settings, the folder's results are from
# Every name each command writes in its --out: what --replace may remove, and never anything else. A rerun
# of the same command replaces its own results; another command's results are never touched.
OWN = {
    "sweep": ("per_seed.parquet", "summary.json", "sweep.rrd", "audit_cpu.parquet", ".parts"),
    "eval": ("per_episode.parquet", "summary.json", "eval.rrd", ".parts"),
    "scene": ("metrics.json", "scene.rrd", "walk.rrd"),
    "compare": ("compare.json", "compare.md", "compare.png", "compare_episodes.json", "compare_episodes.md"),
    "train": ("policy.msgpack", "summary.json", "first_fits.json", "curve.csv", "curve.png", "train.rrd",
              "checkpoints", "eval"),
    "demos": ("data", "meta", ".demos-partial"),
}
# the run file, and the lock file runs of earlier versions left (the lock is now the OS's, on the folder itself)
BOOKKEEPING = (RUN_FILE, ".lock")
# prepare_out_dir's writability probe, there for an instant (or left by a kill in that instant): a run's, never a
# user's. Two processes of one sweep share --out, and process 0 took process 1's probe for a user's file (lead29).
PROBE = ".probe-*"
# Inside the folders a command writes, the files it puts there: a file matching none of these is a user's, and no
# command removes it (a user's data/mine.txt in demos' data/ stays, and the folder is refused).
_DATASET = ("data/chunk-*/file-*.parquet", "meta/info.json", "meta/stats.json", "meta/tasks.parquet",
            "meta/episodes/chunk-*/file-*.parquet")
INSIDE = {
    ".parts": ("manifest.json", "seeds-*.parquet"),
    "checkpoints": ("policy_*.msgpack", "resume.msgpack", "resume-ring-*.f32"),
    "eval": (*OWN["eval"][:-1], *(f".parts/{p}" for p in ("manifest.json", "seeds-*.parquet")), *BOOKKEEPING),
    "data": tuple(p.removeprefix("data/") for p in _DATASET if p.startswith("data/")),
    "meta": tuple(p.removeprefix("meta/") for p in _DATASET if p.startswith("meta/")),
    ".demos-partial": _DATASET,
}


def owns(rel: str, patterns) -> bool:
    """Whether `rel` (a path inside a folder, with /) is one of `patterns`, or the leftover of one's write that did
    not finish: an atomic write's `.NAME.*.tmp`, a recording's `.NAME.partial` (record.partial; a recording that
    failed or was killed left it, and every rerun into the folder was refused for it: the thirteenth pass)."""
    import fnmatch
    import posixpath

    for p in patterns:
        head, base = posixpath.split(p)
        if any(fnmatch.fnmatchcase(rel, posixpath.join(head, q)) for q in (base, f".{base}.*.tmp", f".{base}.partial")):
            return True
    return False


def remove_own(p: Path) -> None:
    """Remove a file a command writes, or the files of one of its folders that it writes there (`INSIDE`), and the
    folders they leave empty; anything else in it stays."""
    p = Path(p)
    if p.is_symlink() or not p.is_dir():
        p.unlink(missing_ok=True)
        return
    for root, dirs, files in os.walk(p, topdown=False):
        rel = Path(root).relative_to(p)
        for f in files:
            if owns((rel / f).as_posix(), INSIDE.get(p.name, ())):
                (Path(root) / f).unlink()
        for d in dirs:
            try:
                (Path(root) / d).rmdir()
            except OSError:  # it holds something this command did not write
                pass
    try:
        p.rmdir()
    except OSError:
        pass


def runs_holding(path: Path):
    """The run folders at or above `path`, nearest first, each with its command: a folder is a run's by its run
    file (one naming no command is not, and neither is a folder merely holding a result's name, a user's)."""
    import json

    for folder in (path, *path.parents):
        try:
            who = json.loads((folder / RUN_FILE).read_text()).get("command")
        except (OSError, ValueError, AttributeError):
            continue
        if who in OWN:
            yield folder, who
