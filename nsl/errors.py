"""The small exception family that every nsl command raises.

The CLI prints any :class:`NslError` as one line and exits non-zero (no
traceback unless ``--debug``).  Messages name the thing, show the value that
was received and say what to do.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class NslError(Exception):
    """Base class: a problem the user can fix, reported as one line."""


class ConfigError(NslError, ValueError):
    """A config field or command-line value is malformed or out of range."""


class UnknownReferenceError(NslError, KeyError):
    """A name (shift, policy, dataset, checkpoint) does not exist."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class CorruptDataError(NslError):
    """A file on disk is truncated, altered or not what it claims to be."""


class IncompatibleVersionError(NslError):
    """A file or database comes from a version of nsl this code cannot read."""


class LockedError(NslError):
    """Another process is writing the same dataset, run or study (it holds the writer lock, :mod:`nsl.locks`)."""


class EnvironmentSetupError(NslError, RuntimeError):
    """The machine lacks something nsl needs (for example an OpenGL backend)."""


def unknown(kind: str, name: str, known: Iterable[str], hint: str = "") -> UnknownReferenceError:
    """Build an UnknownReferenceError that lists the closest known names."""
    known = sorted(set(known))
    close = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    parts = [f"unknown {kind} {name!r}"]
    if close:
        parts.append(f"did you mean {', '.join(repr(c) for c in close)}?")
    elif known:
        shown = ", ".join(known[:12]) + (", ..." if len(known) > 12 else "")
        parts.append(f"known: {shown}")
    if hint:
        parts.append(hint)
    return UnknownReferenceError("; ".join(parts))
