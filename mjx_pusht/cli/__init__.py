"""The command line: `mjx-pusht scene|tree|sweep|eval|compare` (parser and commands only)."""

from mjx_pusht.cli.commands import main

__all__ = ["main"]
