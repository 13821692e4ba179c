"""One error base for everything a user can cause or meet (mink's `exceptions.py` pattern).

The CLI prints an `MjxPushtError` as one line and exits non-zero; anything else that escapes a
command is a bug and keeps its traceback. Each concern subclasses the base where it lives (a
`ValueError` too where the input's value is the problem, so library callers can catch either).
"""

from __future__ import annotations


class MjxPushtError(Exception):
    """Bad input or an unrunnable request: the message says what is wrong, in the library's terms."""


class ConfigError(MjxPushtError, ValueError):
    """A setting's value is out of range or unknown (an obs type, a step count, a shape)."""


class ResetNeeded(MjxPushtError, RuntimeError):
    """An env was stepped or rendered before its first reset (a RuntimeError, as gymnasium's order check raises)."""
