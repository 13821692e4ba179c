"""The `mjx-pusht` commands by name, and `main`: parse, run one, turn bad input into one line and an exit
status. Each command is a thin layer over the library, in a module of its own."""

from __future__ import annotations

import errno
import os
import signal
import sys
import threading
import time
from pathlib import Path

from mjx_pusht.cli.compare import cmd_compare
from mjx_pusht.cli.demos import cmd_demos
from mjx_pusht.cli.eval import cmd_eval
from mjx_pusht.cli.parser import UsageError, build_parser, unread_flags
from mjx_pusht.cli.scene import cmd_scene, cmd_tree
from mjx_pusht.cli.sweep import cmd_sweep
from mjx_pusht.errors import MjxPushtError, missing_extra, needs, one_line


DAGGER_MODULES = ("flax", "optax")  # what DAgger imports of the train extra (PPO adds Brax and orbax)


def cmd_train(args) -> int:
    # before any work: no folder claimed, nothing written
    needs(f"mjx-pusht train --algo {args.algo}", "train", DAGGER_MODULES if args.algo == "dagger" else None)
    from mjx_pusht.cli.train import cmd_train as train

    return train(args)


COMMANDS = {"scene": cmd_scene, "tree": cmd_tree, "sweep": cmd_sweep, "eval": cmd_eval, "compare": cmd_compare,
            "train": cmd_train, "demos": cmd_demos}


# The disk's and the path's refusals: the user's to fix (room, a shorter name, a writable folder), not bugs.
DISK_ERRORS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.ENAMETOOLONG, errno.EROFS, errno.EACCES}


def kept(args) -> str:
    """What an interrupted or failed run of `args.command` leaves in --out, and how to go on."""
    out = getattr(args, "out", None)
    if out is None:  # tree: it writes nothing
        return "nothing was written"
    if args.command == "train" and not (Path(out) / "checkpoints" / "resume.msgpack").is_file():
        return "no checkpoint was written yet (the first comes with the first judgement): rerun without --resume to start"
    if args.command in ("sweep", "eval"):
        from mjx_pusht.study.sweep import kept_chunks

        return kept_chunks(out)
    return {"train": f"the checkpoints written so far are kept in {out}/checkpoints: rerun with --resume to go on",
            "demos": (f"an earlier dataset in {out} is kept as it was (the new one was not finished): rerun to write it"
                      if (Path(out) / "meta" / "info.json").exists() else
                      f"no dataset was finished in {out}: rerun to write it")}.get(args.command, f"nothing finished in {out} was removed: rerun to write it")


def end_interrupted(code: int) -> None:
    """End an interrupted command's process now, without Python's finalization. Ctrl-C can land while the main
    thread waits for an XLA compile on JAX's thread pool; the compile runs on, and at exit JAX's CPU client was torn
    down under it: SIGSEGV after the one-line message, or 10-18 s waiting for it (`train`, 4 and 3 of 16 runs,
    notebook lead22). What the command wrote is whole already: files by rename, --out's lock released; a
    checkpoint being written was waited for (`main`); CPU worker processes are ended here."""
    if "mjx_pusht.backends.cpu" in sys.modules:  # its episodes are not wanted; closed, its semaphores are released
        for pool in list(sys.modules["mjx_pusht.backends.cpu"].FeedbackPool.live):  # (else: "leaked semaphore")
            pool.close(end=True)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


class Signals:
    """SIGINT and SIGTERM while a command runs, as one KeyboardInterrupt: the command's own clean-up runs (chunks,
    checkpoints kept), then one line and exit 130 (SIGINT) or 143 (SIGTERM, 128 + 15, as a shell reports a process
    it ended). `got` remembers which came: a Ctrl-C inside a C extension's import surfaces as `ImportError:
    initialization failed`, which is then the interrupt too. Only the main thread may set handlers; a SIGINT the
    parent ignores (a background job) stays ignored.

    Python runs a handler only when the main thread is back in Python: a main thread waiting in native code (a
    jax.distributed barrier, a long MuJoCo rollout) would hold a SIGTERM off for as long, where `kill`, `timeout` and
    Slurm expect an end. So the signal also wakes a watcher thread (`signal.set_wakeup_fd`), which gives the main
    thread TERM_GRACE seconds to run its handler, and if it has not, ends the process itself with one line and 143."""

    TERM_GRACE = 5.0

    def __init__(self):
        self.got, self.old, self.wake, self.armed = None, {}, None, False

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(sig) is not signal.SIG_IGN:
                    self.old[sig] = signal.signal(sig, self._interrupt)
            if signal.SIGTERM in self.old:
                r, w = os.pipe()
                os.set_blocking(w, False)
                self.wake = (r, w, signal.set_wakeup_fd(w, warn_on_full_buffer=False))
                threading.Thread(target=self._watch, args=(r,), daemon=True, name="sigterm-watch").start()
        return self

    def _watch(self, r: int) -> None:
        with os.fdopen(r, "rb", buffering=0) as pipe:
            while data := pipe.read(16):  # b"" once __exit__ closed the other end
                if signal.SIGTERM not in data:
                    continue
                time.sleep(self.TERM_GRACE)
                if self.wake is None or self.got:  # ended in its own time, or the main thread is handling it
                    return
                os.write(2, b"\nmjx-pusht: terminated (SIGTERM); finished files are whole (each written by rename)\n")
                os._exit(143)

    def _interrupt(self, signum, frame):
        self.got = signum
        if self.armed and _swallows(frame):  # raised there, it is printed ("Exception ignored in") and dropped, and
            # the command ran on to exit 0 (a SIGTERM in JAX's gc callback, during train): sent again once it returned
            threading.Timer(0.02, os.kill, (os.getpid(), signum)).start()
        elif self.armed:
            raise KeyboardInterrupt
        # outside `_main`'s try (this handler is set before the watcher thread starts, and is still set while
        # `with` returns): raised there by `arm`, where it is one line; a SIGINT while the watcher started was a
        # KeyboardInterrupt traceback. After the command, the process is ending with the command's own status.

    def arm(self) -> None:
        """Inside the command's try: a signal from now on is a KeyboardInterrupt there (one that came before, too)."""
        self.armed = True
        if self.got:
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        for sig, handler in self.old.items():  # (not the import's "before the command started" line: it has run)
            signal.signal(sig, signal.SIG_DFL if getattr(handler, "__name__", "") == "_end_early" else handler)
        if self.wake is not None:
            r, w, old = self.wake
            self.wake = None
            signal.set_wakeup_fd(old)
            os.close(w)  # the watcher reads the end of its pipe and returns

    def code(self) -> int:
        return 128 + (self.got or signal.SIGINT)


def _swallows(frame) -> bool:
    """Whether `frame` runs inside code whose exceptions Python prints and drops: a gc callback, a `__del__`."""
    import gc

    callbacks = {getattr(cb, "__code__", None) for cb in gc.callbacks}
    while frame is not None:
        if frame.f_code in callbacks or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input (an `MjxPushtError`) is one line and a non-zero exit; anything else is a bug
    and keeps its traceback."""
    with Signals() as signals:
        try:
            code = _main(argv, signals)
        finally:
            signals.armed = False  # the command has answered: a signal now lets the process end with its status
    if argv is None:  # the process's own command: joined to others, it leaves them together
        from mjx_pusht.study.distributed import leave_peers

        leave_peers(code)
    return code


def _interrupted(args, signals: Signals, argv) -> int:
    from mjx_pusht.io.outputs import finish_background_writes

    if signals.old:  # a second Ctrl-C while the line is written and the writes are waited for: not a traceback
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    code = signals.code()
    what = "terminated (SIGTERM)" if code == 143 else "interrupted"
    if args is None:
        print(f"\nmjx-pusht: {what} before the command started: nothing was written", file=sys.stderr)
    else:
        finish_background_writes()  # a checkpoint being written is whole before the line says what is kept
        print(f"\nmjx-pusht: {what}: {kept(args)}", file=sys.stderr)
    if argv is None:  # the process's own command (not a call from Python): it ends here
        end_interrupted(code)
    return code


def _main(argv, signals: Signals) -> int:
    from mjx_pusht.io.outputs import held_folders

    args = None
    try:
        signals.arm()
        args = build_parser().parse_args(argv)
        unread_flags(args)
        if args.verbose:
            os.environ["MJX_PUSHT_VERBOSE"] = "1"
        if getattr(args, "backend", "cpu") not in ("cpu", "gym-pusht"):  # one that may compile: its cache, at the door
            from mjx_pusht.boundary import jax_cache

            jax_cache()
        with held_folders() as held:  # the --out folder is locked while the command runs
            code = COMMANDS[args.command](args)
            held.failed = code != 0
        if code == 130 and signals.got:  # a command that caught the interrupt and said what it kept
            if argv is None:  # ends now: atexit's jax.distributed shutdown would wait for peers still running
                end_interrupted(signals.code())
            return signals.code()
        return code
    except UsageError as e:
        print(f"mjx-pusht: error: {one_line(str(e))}", file=sys.stderr)
        return 2
    except MjxPushtError as e:
        print(f"mjx-pusht: error: {one_line(str(e))}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return _interrupted(args, signals, argv)
    except BrokenPipeError:  # the reader went away (`mjx-pusht tree --json | head`): nothing more to say to it
        if argv is None:  # Python's own flush of stdout at exit would fail again, with a line of its own
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except OSError as e:
        if args is None or e.errno not in DISK_ERRORS:
            raise  # not the disk or the path: a bug, with its traceback
        print(f"mjx-pusht: error: writing {e.filename or args.out} failed ({e.strerror}); {kept(args)}", file=sys.stderr)
        return 1
    except ImportError as e:  # an optional extra's module met where no `requires` stood: still one line
        if signals.got:  # Ctrl-C inside an extension's import: "initialization failed"
            return _interrupted(args, signals, argv)
        err = missing_extra(e, f"mjx-pusht {argv[0] if argv else sys.argv[1]}")
        if err is None:
            raise
        print(f"mjx-pusht: error: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
