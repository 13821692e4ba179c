"""What every batch command (sweep, eval) does around its rows: claim the folder and build the backend
before the first row (`start_batch`), time its phases (`Clock`), record a few rows (`record`), warn
about rows MuJoCo warned on (`warn_mujoco`)."""

from __future__ import annotations

from pathlib import Path


class Clock:
    """Seconds per phase of a command, for summary.json's `timing` block."""

    def __init__(self):
        import time

        self._now = time.perf_counter
        self.t = self._now()
        self.laps: dict[str, float] = {}

    def lap(self, name: str) -> float:
        t = self._now()
        self.laps[name] = t - self.t
        self.t = t
        return self.laps[name]

    def report(self, sweep: dict) -> dict:
        """The command's phases, with the sweep's own (start poses, compile, rollout, writing) inside it."""
        out = {k: round(v, 3) for k, v in self.laps.items()}
        out.update({f"sweep.{k}": round(v, 3) for k, v in sweep.items() if k != "rollout_and_compile"})
        return out


def start_batch(command: str, out, seeds, name: str, why: str, config: dict, scenario, *, replace: bool = False,
                resume: bool = False, check: bool = True, reads=(), share: bool = False, writes=(), earlier=()):
    """What every batch command does before its first row: the rows, a writable `out` that holds no
    other unfinished run (nor, replaced, a file in `reads`), the banner, and the backend (which compiles the
    scene and checks its tree). Returns (row seeds, their parameter combinations, out, banner, clock, backend)."""
    from mjx_pusht.backends.factory import make_backend
    from mjx_pusht.backends.cpu import default_threads
    from mjx_pusht.io.banner import Banner
    from mjx_pusht.io.outputs import claim_out_dir, prepare_out_dir, remove_own
    from mjx_pusht.study.sweep import PARTS, ResumeError, check_resumable, fingerprint, rows_for

    n_combos = len(scenario.grid())
    if n_combos > 1:  # a row per seed and parameter combination (--seeds alone was checked by parse_seeds)
        from mjx_pusht.boundary import BYTES_PER_SEED, fits

        fits(f"--seeds x --param ({len(seeds):,} seeds x {n_combos:,} combinations)", len(seeds) * n_combos,
             BYTES_PER_SEED, "fewer seeds or combinations a run")
    row_seeds, combos = rows_for(seeds, n_combos)
    if resume and check and not (Path(out) / PARTS).is_dir() and not (Path(out) / "summary.json").is_file():
        # as train's --resume without a checkpoint: a fresh run under --resume was silently a fresh run
        raise ResumeError(f"--resume: {out} holds no unfinished {command} (no .parts) and no finished one; "
                          "nothing to resume (run without --resume to start)")
    # with several processes process 0 makes and claims the folder for all; another process making it too left an
    # empty folder behind when process 0 refused it (the fifteenth pass)
    out = prepare_out_dir(out) if check else Path(out)

    def resumable(path: Path, same: bool) -> None:
        if replace and not resume and (path / PARTS).is_dir():  # --replace: its own unfinished chunks go
            remove_own(path / PARTS)
            print(f"--replace: removed the unfinished {command}'s chunks in {path}")
        check_resumable(path, row_seeds, config, resume)

    if check:  # with several processes, process 0 checks, locks (and clears) the folder for all
        claim_out_dir(out, command, fingerprint(row_seeds, config), replace=replace, reads=reads, share=share,
                      check=resumable, writes=writes, earlier=earlier)
    banner = Banner(command)
    print(f"backend: {name} ({why})")
    clock = Clock()
    # cpu: feedback episodes take a process per core (the sweep's open-loop rollout threads itself)
    backend = make_backend(name, scenario, workers=default_threads() if command == "eval" else 1)
    clock.lap("backend_setup_and_tree_check")
    return row_seeds, combos, out, banner, clock, backend


def record(path: Path, rows: str, backend, r, combos, pick, writer, summary: dict, clock, *, rerun: bool,
           n: int) -> None:
    """The recording of a batch command: the rows `pick()` chooses (when `rerun` and `n` > 0) rerun with a
    trace and written by `writer` (or an earlier run's recording removed when this run is not recorded);
    its time joins the summary."""
    from mjx_pusht.io.outputs import atomic_write_json, drop_stale
    from mjx_pusht.io.record import row_labels, viewer_command

    if not (rerun and n > 0):
        drop_stale(path)
        return
    shown = pick()
    traced = backend.run(r.seeds[shown], trace=True, combos=combos[shown])
    try:
        writer(path, backend.model, traced, r, row_labels(r, shown))
    except BaseException:  # whole or not at all: the half-written recording goes too (a kill leaves it: own.owns)
        from mjx_pusht.io.record import partial

        partial(path).unlink(missing_ok=True)
        raise
    summary["timing"]["recording"] = round(clock.lap("recording"), 3)
    atomic_write_json(path.parent / "summary.json", summary)
    print(f"recording: {path} ({len(shown)} {rows} side by side) - open it with: {viewer_command(path)}")


def warn_mujoco(summary: dict, rows: str) -> None:
    """One line naming the rows on which MuJoCo raised a warning, if any did."""
    if summary["n_mujoco_warnings"]:
        print(f"WARNING: MuJoCo raised {', '.join(summary['mujoco_warnings'])} on {summary['n_mujoco_warnings']} {rows} "
              f"(flagged in mujoco_warnings, never counted rigid; mjWARN_INERTIA: a singular model, e.g. a "
              f"near-zero mass): {summary['mujoco_warning_seeds'][:10]}")
