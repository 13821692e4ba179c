"""The `mjx-pusht` commands by name, and `main`: parse, run one, turn bad input into one line and an exit
status. Each command is a thin layer over the library, in a module of its own."""

from __future__ import annotations

import os
import sys

from mjx_pusht.cli.compare import cmd_compare
from mjx_pusht.cli.demos import cmd_demos
from mjx_pusht.cli.eval import cmd_eval
from mjx_pusht.cli.parser import UsageError, build_parser
from mjx_pusht.cli.scene import cmd_scene, cmd_tree
from mjx_pusht.cli.sweep import cmd_sweep
from mjx_pusht.errors import MjxPushtError, missing_extra, needs


def cmd_train(args) -> int:
    needs("mjx-pusht train", "train")  # before any work: no folder claimed, nothing written
    from mjx_pusht.cli.train import cmd_train as train

    return train(args)


COMMANDS = {"scene": cmd_scene, "tree": cmd_tree, "sweep": cmd_sweep, "eval": cmd_eval, "compare": cmd_compare,
            "train": cmd_train, "demos": cmd_demos}


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input (an `MjxPushtError`) is one line and a non-zero exit; anything else is a bug
    and keeps its traceback."""
    from mjx_pusht.io.outputs import held_folders

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
    except ImportError as e:  # an optional extra's module met where no `requires` stood: still one line
        err = missing_extra(e, f"mjx-pusht {argv[0] if argv else sys.argv[1]}")
        if err is None:
            raise
        print(f"mjx-pusht: error: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
