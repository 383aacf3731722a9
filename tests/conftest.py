"""Shared fixtures: every test gets its own empty workspace (NSL_HOME)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # must precede any mujoco import

import pytest


@pytest.fixture(autouse=True)
def nsl_home(tmp_path_factory, monkeypatch):
    home = tmp_path_factory.mktemp("nsl_home")
    monkeypatch.setenv("NSL_HOME", str(home))
    return home


def run_cli(*argv: str) -> int:
    """Run the real ``nsl`` entry point in-process."""
    from nsl.cli import main

    return main(list(argv))
