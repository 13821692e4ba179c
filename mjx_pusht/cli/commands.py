"""The `mjx-pusht` commands by name, and `main`: parse, run one, turn bad input into one line and an exit
status. Each command is a thin layer over the library, in a module of its own."""

from __future__ import annotations

import errno
import os
import sys
from pathlib import Path

from mjx_pusht.cli.compare import cmd_compare
from mjx_pusht.cli.demos import cmd_demos
from mjx_pusht.cli.eval import cmd_eval
from mjx_pusht.cli.parser import UsageError, build_parser
from mjx_pusht.cli.scene import cmd_scene, cmd_tree
from mjx_pusht.cli.sweep import cmd_sweep
from mjx_pusht.errors import MjxPushtError, missing_extra, needs


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
    if args.command == "train" and not (Path(out) / "checkpoints" / "resume.msgpack").is_file():
        return "no checkpoint was written yet (the first comes with the first judgement): rerun without --resume to start"
    return {"sweep": f"the finished chunks are kept in {out}/.parts: rerun with --resume to finish",
            "eval": f"the finished chunks are kept in {out}/.parts: rerun with --resume to finish",
            "train": f"the checkpoints written so far are kept in {out}/checkpoints: rerun with --resume to go on",
            "demos": f"an earlier dataset in {out} is kept as it was (the new one was not finished): rerun to write "
                     "it"}.get(args.command, f"nothing finished in {out} was removed: rerun to write it")


def end_interrupted(code: int) -> None:
    """End an interrupted command's process now, without Python's finalization. Ctrl-C can land while the main
    thread waits for an XLA compile on JAX's thread pool; the compile runs on, and at exit JAX's CPU client was torn
    down under it: SIGSEGV after the one-line message, or 10-18 s waiting for it (`train`, 4 and 3 of 16 runs,
    notebook lead22). What the command wrote is whole already: files by rename, --out's lock released; a
    checkpoint being written was waited for (`main`)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input (an `MjxPushtError`) is one line and a non-zero exit; anything else is a bug
    and keeps its traceback."""
    from mjx_pusht.io.outputs import finish_background_writes, held_folders

    args = None
    try:
        args = build_parser().parse_args(argv)
        if args.verbose:
            os.environ["MJX_PUSHT_VERBOSE"] = "1"
        with held_folders():  # the --out folder is locked while the command runs
            return COMMANDS[args.command](args)
    except UsageError as e:
        print(f"mjx-pusht: error: {e}", file=sys.stderr)
        return 2
    except MjxPushtError as e:
        print(f"mjx-pusht: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if args is None:
            raise
        finish_background_writes()  # a checkpoint being written is whole before the line says what is kept
        print(f"\nmjx-pusht: interrupted: {kept(args)}", file=sys.stderr)
        if argv is None:  # the process's own command (not a call from Python): it ends here
            end_interrupted(130)
        return 130
    except OSError as e:
        if args is None or e.errno not in DISK_ERRORS:
            raise  # not the disk or the path: a bug, with its traceback
        print(f"mjx-pusht: error: writing {e.filename or args.out} failed ({e.strerror}); {kept(args)}", file=sys.stderr)
        return 1
    except ImportError as e:  # an optional extra's module met where no `requires` stood: still one line
        err = missing_extra(e, f"mjx-pusht {argv[0] if argv else sys.argv[1]}")
        if err is None:
            raise
        print(f"mjx-pusht: error: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
