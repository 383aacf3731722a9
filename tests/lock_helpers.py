"""Run the real ``nsl`` command in a subprocess that stops at a chosen call until the test lets it go.

:func:`start_held` patches ``MODULE.ATTR`` in the child so that its call number ``after + 1`` writes the child's
pid to ``flag`` and waits until ``go`` exists (or never returns when ``go`` is None: the test kills it).  The
child runs ``nsl ARGV...`` with ``sys.argv`` as the command line shows it, so a lock's holder record names it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_HOLD = """
import importlib, os, sys, time
from pathlib import Path

module, attr, after, flag, go = sys.argv[1:6]
target = importlib.import_module(module)
original = getattr(target, attr)
calls = [0]


def held(*args, **kwargs):
    calls[0] += 1
    if calls[0] == int(after) + 1:
        Path(flag).write_text(str(os.getpid()))
        while go == "-" or not Path(go).exists():
            time.sleep(0.02)
    return original(*args, **kwargs)


setattr(target, attr, held)
sys.argv = ["nsl", *sys.argv[6:]]
from nsl.cli import main

sys.exit(main())
"""


def nsl_argv(*argv: str) -> list[str]:
    return [sys.executable, "-m", "nsl", *argv]


def popen(argv: list[str], **kwargs) -> subprocess.Popen:
    """A child in its own process group (``os.killpg`` ends it and its workers), stderr captured as text."""
    kwargs.setdefault("stdout", subprocess.PIPE)
    return subprocess.Popen(
        argv, cwd=ROOT, env={**os.environ}, stderr=subprocess.PIPE, text=True, process_group=0, **kwargs
    )


def start_held(
    tmp: Path, module: str, attr: str, *argv: str, after: int = 0, release: bool = True
) -> tuple[subprocess.Popen, Path, Path]:
    """Start ``nsl ARGV`` held at ``MODULE.ATTR``; returns (process, flag file, go file).  Waits for the flag."""
    flag, go = tmp / f"held-{attr}.pid", tmp / f"go-{attr}"
    flag.unlink(missing_ok=True)
    go.unlink(missing_ok=True)
    proc = popen([sys.executable, "-c", _HOLD, module, attr, str(after), str(flag), str(go) if release else "-", *argv])
    wait_for(lambda: flag.exists() or proc.poll() is not None, what=f"{attr} to be reached")
    assert flag.exists(), f"the held process exited early: {proc.communicate()[1][-2000:]}"
    return proc, flag, go


def wait_for(condition, what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def read_line_containing(proc: subprocess.Popen, text: str, timeout: float = 120.0) -> str:
    """Read ``proc``'s stderr until a line holds ``text``; returns that line."""
    assert proc.stderr is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if text in line:
            return line.strip()
        if not line and proc.poll() is not None:
            break
    raise AssertionError(f"no stderr line with {text!r}")
