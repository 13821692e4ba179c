"""One error base for everything a user can cause or meet (mink's `exceptions.py` pattern).

The CLI prints an `MjxPushtError` as one line and exits non-zero; anything else that escapes a
command is a bug and keeps its traceback. Each concern subclasses the base where it lives (a
`ValueError` too where the input's value is the problem, so library callers can catch either).
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util


class MjxPushtError(Exception):
    """Bad input or an unrunnable request: the message says what is wrong, in the library's terms, on one line
    (a value shown in it, an array's repr say, has its line breaks folded here, whoever raised it)."""

    def __init__(self, *args):
        if args and isinstance(args[0], str):
            args = (one_line(args[0]), *args[1:])
        super().__init__(*args)


def one_line(text: str) -> str:
    """`text` on one line: any line break (\\n, \\r, a Unicode one a value echoed in the message held) folded into
    a space; a text of one line is returned as it is."""
    return text if len(text.strip().splitlines()) <= 1 else " ".join(text.split())


class ConfigError(MjxPushtError, ValueError):
    """A setting's value is out of range or unknown (an obs type, a step count, a shape)."""


class ResetNeeded(MjxPushtError, RuntimeError):
    """An env was stepped or rendered before its first reset (a RuntimeError, as gymnasium's order check raises)."""


# The optional extras (pyproject.toml's [project.optional-dependencies]) and the top-level modules each brings
EXTRAS: dict[str, tuple[str, ...]] = {
    "warp": ("warp",),
    "gym": ("gymnasium",),
    "video": ("imageio", "imageio_ffmpeg"),
    "brax": ("brax",),
    "train": ("flax", "optax", "orbax", "brax"),
}


class MissingExtra(MjxPushtError, ImportError):
    """An optional dependency is not installed: the one line names the extra that brings it."""


def missing_extra(error: ImportError, what: str, extra: str | None = None) -> MissingExtra | None:
    """The one-line error for `error` if the module it could not import belongs to an extra (`extra` first, the
    one the caller needs), else None: a missing module no extra brings is not the user's to fix by installing."""
    top = (getattr(error, "name", None) or "").split(".")[0]
    names = ([extra] if extra else []) + [e for e in EXTRAS if e != extra]
    found = next((e for e in names if top in EXTRAS[e]), None)
    if found is None:
        return None
    return MissingExtra(f"{what} needs {top}, which is not installed: pip install 'mjx-pusht[{found}]'")


@contextlib.contextmanager
def requires(what: str, extra: str):
    """Around an optional import (or the work that imports lazily): a missing module of an extra becomes one line
    naming the extra to install; any other ImportError is a bug and keeps its traceback."""
    try:
        yield
    except ImportError as e:
        if isinstance(e, MissingExtra):
            raise
        err = missing_extra(e, what, extra)
        if err is None:
            raise
        raise err from None


def needs(what: str, extra: str, modules: tuple[str, ...] | None = None) -> None:
    """Check that the modules of `extra` the work uses (`modules`; all of them if None) are installed, before any
    work: `requires`' one line if one is missing. Found, not imported: importing Brax and flax cost every `train`
    call, a refusal of a bad flag included, 4.7 s where it now takes 0.45 s (this 2-core CPU). (DAgger uses flax
    and optax alone: a GPU host without Brax trains it.)"""
    with requires(what, extra):
        for name in EXTRAS[extra] if modules is None else modules:
            if importlib.util.find_spec(name) is None:  # None too where sys.modules holds None (tests/test_extras.py)
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
