"""The package version and the code version recorded with every dataset, checkpoint and run."""

from __future__ import annotations

import functools
import os
import subprocess
from typing import Any

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@functools.cache
def installed_version() -> str:
    """The version pyproject.toml states, as the installed package's metadata records it."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("nsl")
    except PackageNotFoundError:  # a source tree run without installing: read pyproject.toml itself
        import tomllib

        try:
            with open(os.path.join(_ROOT, "pyproject.toml"), "rb") as f:
                return str(tomllib.load(f)["project"]["version"])
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "0+unknown"


def __getattr__(name: str) -> Any:
    """``__version__``, read on first use (importing importlib.metadata costs more than the rest of ``import nsl``)."""
    if name == "__version__":
        globals()["__version__"] = value = installed_version()
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
            return f"{installed_version()}+g{out.stdout.strip()}{'.dirty' if dirty else ''}"
    except (OSError, subprocess.SubprocessError):
        pass
    return installed_version()
