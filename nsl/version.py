"""The package version and the code version recorded with every dataset, checkpoint and run."""

from __future__ import annotations

import os
import subprocess

__version__ = "0.1.0"

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def code_version() -> str:
    """The package version plus the git commit (``+gSHA[.dirty]``) when run from a checkout."""
    try:
        out = subprocess.run(
            ["git", "-C", _ROOT, "rev-parse", "--short=12", "HEAD"], capture_output=True, text=True, timeout=5
        )
        if out.returncode == 0:
            dirty = subprocess.run(
                ["git", "-C", _ROOT, "status", "--porcelain", "--untracked-files=no"],
                capture_output=True,
                text=True,
                timeout=5,
            ).stdout.strip()
            return f"{__version__}+g{out.stdout.strip()}{'.dirty' if dirty else ''}"
    except (OSError, subprocess.SubprocessError):
        pass
    return __version__
