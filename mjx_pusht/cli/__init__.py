"""The command line: `mjx-pusht scene|tree|sweep|eval|compare|train`: the parser (parser.py), the command
table and `main` (commands.py), and one thin module per command over the library."""

from mjx_pusht.cli.commands import main

__all__ = ["main"]
