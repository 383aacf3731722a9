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


def recorded_calls(script, tmp_path, *args: str, **env: str) -> list[list[str]]:
    """Run a shell recipe (with ``args``) and a recording stand-in for `nsl` (``$NSL``).

    Returns the argument lists it would run.
    """
    import shlex
    import subprocess

    log = tmp_path / "calls"
    fake = tmp_path / "nsl"
    fake.write_text(f'#!/usr/bin/env bash\nprintf "%q " "$@" >> {log}\necho >> {log}\n')
    fake.chmod(0o755)
    env = {**os.environ, "NSL": str(fake), "NSL_HOME": str(tmp_path / "home"), **env}
    subprocess.run(["bash", str(script), *args], env=env, check=True, capture_output=True)
    return [shlex.split(line) for line in log.read_text().splitlines()]
