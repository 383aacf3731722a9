"""Shared fixtures: every test gets its own empty workspace (NSL_HOME); a real S3 server (moto) on 127.0.0.1."""

from __future__ import annotations

import os
import socket
from dataclasses import dataclass, field

os.environ.setdefault("MUJOCO_GL", "egl")  # must precede any mujoco import

import pytest

# `make test` runs the suite on two pytest-xdist workers (``--dist loadgroup --no-loadscope-reorder``).  The tests
# that share the study folder's session-scoped runs (the mini and the micro plan, each a minute or more of CPU) join
# one group per run, wherever their module is; a module whose tests share one run only joins that run's group whole
# (``pytestmark``), so its module-scoped fixtures (a cluster, a transfer study) are built once, beside the run.  Every
# other module is a group of its own.  The shared runs' groups go first, so the longest chains of work start at once
# and the rest fills in beside them.  Each worker computes on one thread (two workers on two cores): with torch's
# two threads each they wait on each other (ungrouped, the suite took 713 s so and 646 s with one; docs/testing.md).
SHARED_RUNS = ("mini_run", "micro_run")
if os.environ.get("PYTEST_XDIST_WORKER"):
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def _group(item) -> str:
    mark = item.get_closest_marker("xdist_group")
    return mark.args[0] if mark is not None else item.nodeid.split("::", 1)[0]


def pytest_itemcollected(item):
    if item.get_closest_marker("xdist_group") is None:
        shared = [f for f in SHARED_RUNS if f in getattr(item, "fixturenames", ())]
        item.add_marker(pytest.mark.xdist_group(shared[0] if shared else item.nodeid.split("::", 1)[0]))


def pytest_collection_modifyitems(config, items):
    items.sort(key=lambda item: _group(item) not in SHARED_RUNS)  # stable: the rest keep their order


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
