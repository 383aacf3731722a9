"""One writer per thing: an OS file lock beside the folder it protects.

Every writer of a dataset (``datasets/NAME``), a run (``runs/NAME``) or a study (``studies/NAME``) holds
:func:`writer_lock` on that folder while it writes.  The lock is an OS lock (``flock`` through ``filelock``,
the same kind SQLite, DVC and the Hugging Face cache take): the kernel releases it when its holder exits, even
by ``kill -9``, so a stale lock never needs cleaning up and the same command run again resumes.

The lock file lies beside the folder it protects, ``PARENT/.NAME.lock`` (``datasets/.grasp-base.lock``), so
taking it creates nothing inside the folder (a refused command leaves no folder behind); ``.NAME.lock.json``
beside it names the holder (pid, command line, start time in UTC), which a refused writer quotes.  Both live
outside every dataset version, run, checkpoint and manifest, and their names start with a dot, so listings,
hashes and pushes skip them; the lock file stays after a release (waiters share its inode).  Readers never take
the lock.  In one process the lock is reentrant per thread (a continual run's collection can take the dataset's
lock while the run holds its own); another thread of the same process is refused like another process.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from nsl.errors import LockedError

LOCK_SUFFIX = ".lock"
HOLDER_SUFFIX = ".lock.json"
GRACE_S = 0.5  # a writer that does not wait still retries this long: a status probe holds the lock for microseconds
_COMMAND_CHARS = 120


def lock_file(folder: Path | str) -> Path:
    """The lock file of ``folder``: ``PARENT/.NAME.lock``."""
    folder = Path(os.path.abspath(folder))
    return folder.parent / f".{folder.name}{LOCK_SUFFIX}"


def holder_file(folder: Path | str) -> Path:
    """The holder's record of ``folder``'s lock: ``PARENT/.NAME.lock.json``."""
    folder = Path(os.path.abspath(folder))
    return folder.parent / f".{folder.name}{HOLDER_SUFFIX}"


def is_lock_name(name: str) -> bool:
    """Whether a file name is a lock file or a holder's record (never a temporary file to collect)."""
    return name.startswith(".") and name.endswith((LOCK_SUFFIX, HOLDER_SUFFIX))


def _lock(folder: Path):
    from filelock import FileLock

    # One instance per path in a process (reentrant per thread); no soft fallback: a lock must die with its holder.
    return FileLock(lock_file(folder), is_singleton=True, fallback_to_soft=False)


def _command() -> str:
    argv = list(sys.argv) or ["python"]
    program = Path(argv[0])
    argv[0] = (program.parent.name if program.name == "__main__.py" else program.name) or "python"  # python -m nsl
    text = " ".join(" ".join(a.split()) for a in argv)
    return text if len(text) <= _COMMAND_CHARS else text[: _COMMAND_CHARS - 3] + "..."


def _read_holder(folder: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(holder_file(folder).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def describe(holder: dict[str, Any] | None) -> str:
    """``process 1234 (nsl collect ...) since 2026-12-05T02:31:10Z``, or ``another process`` when unknown."""
    if not holder or not holder.get("pid"):
        return "another process"
    return f"process {holder['pid']} ({holder.get('command', '?')}) since {holder.get('since', '?')}"


def holder(folder: Path) -> dict[str, Any] | None:
    """Who holds the writer lock of ``folder`` (``{"pid", "command", "since"}``; ``{}`` when its record is
    unreadable), or None when nobody does.  Probes the lock without waiting and creates nothing."""
    from filelock import Timeout

    folder = Path(folder)
    if not lock_file(folder).exists():
        return None
    lock = _lock(folder)
    if lock.is_locked:  # this thread holds it
        return _read_holder(folder) or {}
    try:
        lock.acquire(blocking=False)
    except Timeout:
        return _read_holder(folder) or {}
    lock.release()
    return None


@contextmanager
def writer_lock(folder: Path | str, what: str, *, wait: bool = False) -> Iterator[None]:
    """Hold the writer lock of ``folder`` for the ``with`` block (the folder itself is neither needed nor made).

    ``what`` names the thing in messages (``dataset 'grasp-base'``).  When another process holds the lock,
    raise :class:`~nsl.errors.LockedError` naming it, or with ``wait`` print one line to stderr and wait.
    """
    from filelock import Timeout

    folder = Path(folder)
    lock_file(folder).parent.mkdir(parents=True, exist_ok=True)
    lock = _lock(folder)
    outer = not lock.is_locked
    try:
        lock.acquire(timeout=GRACE_S)
    except Timeout:
        held_by = _holder_record(folder)
        if not wait:
            raise LockedError(
                f"{what} is being written by {describe(held_by)}; wait for it to finish, or pass --wait"
            ) from None
        print(f"nsl: {what} is being written by {describe(held_by)}; waiting for it", file=sys.stderr, flush=True)
        lock.acquire()  # blocks until the holder exits or releases it
    try:
        if outer:
            from nsl.workspace import atomic_write_json

            since = dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
            atomic_write_json(holder_file(folder), {"pid": os.getpid(), "command": _command(), "since": since})
        yield
    finally:
        try:
            if outer:  # before the release: afterwards the record may be the next holder's
                holder_file(folder).unlink(missing_ok=True)
        finally:
            lock.release()


def _holder_record(folder: Path) -> dict[str, Any] | None:
    """The holder's record; a holder that has just taken the lock writes it within moments."""
    for _ in range(20):
        record = _read_holder(folder)
        if record:
            return record
        time.sleep(0.05)
    return None


def dataset_lock(name: str, *, wait: bool = False):
    """The writer lock of dataset ``name`` (``$NSL_HOME/datasets/.NAME.lock``); ``name`` must be checked."""
    from nsl.workspace import datasets_dir

    return writer_lock(datasets_dir() / name, f"dataset {name!r}", wait=wait)


def run_lock(name: str, *, wait: bool = False):
    """The writer lock of run ``name`` (``$NSL_HOME/runs/.NAME.lock``): train, continual, online, features."""
    from nsl.workspace import runs_dir

    return writer_lock(runs_dir() / name, f"run {name!r}", wait=wait)
