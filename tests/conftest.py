"""Shared fixtures: every test gets its own empty workspace (NSL_HOME); a real S3 server (moto) on 127.0.0.1."""

from __future__ import annotations

import os
import socket
from dataclasses import dataclass, field

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


# ----------------------------------------------------------------------- S3
@dataclass
class S3Server:
    endpoint: str
    requests: list[tuple[str, str]] = field(default_factory=list)  # (method, path) of every request served

    def puts(self, since: int = 0) -> list[str]:
        """Paths of object uploads (PUT with a key) among the requests from index ``since``."""
        return [p for m, p in self.requests[since:] if m == "PUT" and p.strip("/").count("/") >= 1]


@pytest.fixture(scope="session")
def s3_server():
    """moto's S3 server on 127.0.0.1 (a free port), with a log of the requests it serves."""
    from moto.server import ThreadedMotoServer

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    info = S3Server(f"http://127.0.0.1:{port}")
    app = server._server.app

    def counting(environ, start_response):
        info.requests.append((environ["REQUEST_METHOD"], environ.get("PATH_INFO", "")))
        return app(environ, start_response)

    server._server.app = counting
    yield info
    server.stop()


@pytest.fixture
def s3(s3_server, monkeypatch, request):
    """A fresh bucket on the moto server; fsspec is pointed at it through its own configuration."""
    import fsspec.config
    import s3fs

    for var in ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY"):
        monkeypatch.setenv(var, "testing")  # dummy credentials: the server accepts any
    monkeypatch.delenv("AWS_PROFILE", raising=False)
    monkeypatch.setitem(fsspec.config.conf, "s3", {"client_kwargs": {"endpoint_url": s3_server.endpoint}})
    s3fs.S3FileSystem.clear_instance_cache()
    bucket = ("nsl-" + request.node.name.lower().replace("_", "-").replace("[", "-").replace("]", ""))[:40].rstrip("-")
    fs = s3fs.S3FileSystem(client_kwargs={"endpoint_url": s3_server.endpoint})
    fs.mkdir(bucket)
    yield f"s3://{bucket}"
    s3fs.S3FileSystem.clear_instance_cache()
