"""A remote's failures end in one nsl line that names the remote and says the fix, never a botocore traceback.

Each kind is produced for real against moto's S3 server on 127.0.0.1: no credentials at all, credentials
the server refuses (IAM authorisation switched on in moto), a bucket that does not exist, and a port on
127.0.0.1 where nothing listens.  Every case runs through the CLI entry point (``nsl.cli.main``); the
first one also as a separate ``python -m nsl`` process, as a user in a plain shell would run it.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from tests.conftest import run_cli
from tests.datasets.conftest import SYNTH_SPEC, synth_episode

ROOT = Path(__file__).resolve().parents[2]
AWS_VARS = ("AWS_ACCESS_KEY_ID", "AWS_SECRET_ACCESS_KEY", "AWS_SESSION_TOKEN", "AWS_PROFILE", "AWS_DEFAULT_PROFILE")


@pytest.fixture
def aws(monkeypatch, tmp_path):
    """No AWS configuration but what a test sets; never the instance-metadata service (no network)."""
    for var in AWS_VARS:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("AWS_SHARED_CREDENTIALS_FILE", str(tmp_path / "no-credentials"))
    monkeypatch.setenv("AWS_CONFIG_FILE", str(tmp_path / "no-config"))
    monkeypatch.setenv("AWS_EC2_METADATA_DISABLED", "true")
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-east-1")
    import s3fs

    s3fs.S3FileSystem.clear_instance_cache()
    yield monkeypatch
    s3fs.S3FileSystem.clear_instance_cache()


def endpoint(monkeypatch, url: str, **conf) -> None:
    import fsspec.config

    monkeypatch.setitem(fsspec.config.conf, "s3", {"client_kwargs": {"endpoint_url": url}, **conf})


def one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "botocore" not in err.lower(), err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("nsl: error: "), err
    return lines[0]


def attempt(kind: str, url: str) -> list[str]:
    """The CLI arguments that pull from or push a small dataset to ``url``."""
    if kind == "push":
        from nsl.datasets import api

        api.write_dataset("grasp-err", [synth_episode(i, 3, success=i == 0) for i in range(2)], SYNTH_SPEC, 16, 2)
        return ["push", "data:grasp-err@v1", url]
    return ["pull", url]


@pytest.mark.parametrize("kind", ["pull", "push"])
def test_no_credentials(kind, s3_server, aws, capsys):
    endpoint(aws, s3_server.endpoint)
    url = "s3://nsl-creds/grasp"
    assert run_cli(*attempt(kind, url)) == 2
    line = one_line(capsys)
    assert f"remote {url}: no credentials" in line
    assert "AWS_ACCESS_KEY_ID" in line and "AWS_PROFILE" in line  # the fix


def test_no_credentials_in_a_plain_shell(s3_server, tmp_path):
    """The reported case: `nsl pull s3://bucket/x` in a fresh process without any AWS configuration."""
    env = {k: v for k, v in os.environ.items() if k not in AWS_VARS and not k.startswith("FSSPEC_")}
    env.update(
        NSL_HOME=str(tmp_path / "home"),
        PYTHONPATH=str(ROOT),
        AWS_EC2_METADATA_DISABLED="true",
        AWS_SHARED_CREDENTIALS_FILE=str(tmp_path / "none"),
        AWS_CONFIG_FILE=str(tmp_path / "none"),
        AWS_DEFAULT_REGION="us-east-1",
        AWS_ENDPOINT_URL=s3_server.endpoint,
    )
    r = subprocess.run(
        [sys.executable, "-m", "nsl", "pull", "s3://bucket/x"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert lines[0].startswith("nsl: error: remote s3://bucket/x: no credentials") and "AWS_ACCESS_KEY_ID" in lines[0]


@pytest.fixture
def refused_keys(s3_server, aws):
    """A bucket holding a dataset, and the keys of an IAM user with no policy: moto then denies every request."""
    import boto3
    from moto import settings
    from moto.core.responses import ActionAuthenticatorMixin

    aws.setenv("AWS_ACCESS_KEY_ID", "testing")
    aws.setenv("AWS_SECRET_ACCESS_KEY", "testing")
    endpoint(aws, s3_server.endpoint)
    s3 = boto3.client("s3", endpoint_url=s3_server.endpoint)
    s3.create_bucket(Bucket="nsl-locked")
    s3.put_object(Bucket="nsl-locked", Key="grasp/v1/manifest.json", Body=b'{"files": {}, "hash": "sha256:0"}')
    iam = boto3.client("iam", endpoint_url=s3_server.endpoint)
    user = f"nobody-{uuid.uuid4().hex[:8]}"
    iam.create_user(UserName=user)
    key = iam.create_access_key(UserName=user)["AccessKey"]
    before = settings.INITIAL_NO_AUTH_ACTION_COUNT
    settings.INITIAL_NO_AUTH_ACTION_COUNT = 0  # moto checks every request from now on (the server is in-process)
    ActionAuthenticatorMixin.request_count = 0
    aws.setenv("AWS_ACCESS_KEY_ID", key["AccessKeyId"])
    aws.setenv("AWS_SECRET_ACCESS_KEY", key["SecretAccessKey"])
    try:
        yield "s3://nsl-locked/grasp"
    finally:
        settings.INITIAL_NO_AUTH_ACTION_COUNT = before


@pytest.mark.parametrize("kind", ["pull", "push"])
def test_permission_denied(kind, refused_keys, capsys):
    assert run_cli(*attempt(kind, refused_keys)) == 2
    line = one_line(capsys)
    assert f"remote {refused_keys}: permission denied" in line and "Access Denied" in line
    assert "credentials this remote grants access to" in line and "AWS_PROFILE" in line


def test_unknown_access_key_is_permission_denied(refused_keys, aws, capsys):
    aws.setenv("AWS_ACCESS_KEY_ID", "AKIANOSUCHKEY0000000")
    assert run_cli("pull", refused_keys) == 2
    line = one_line(capsys)
    assert f"remote {refused_keys}: permission denied" in line and "Access Key Id" in line


def test_missing_bucket(s3_server, aws, capsys):
    aws.setenv("AWS_ACCESS_KEY_ID", "testing")
    aws.setenv("AWS_SECRET_ACCESS_KEY", "testing")
    endpoint(aws, s3_server.endpoint)
    assert run_cli("pull", "s3://nsl-no-such-bucket/grasp@v1") == 2
    line = one_line(capsys)
    assert "remote s3://nsl-no-such-bucket/grasp: bucket 'nsl-no-such-bucket' does not exist" in line
    assert "check the URL" in line


@pytest.mark.parametrize("kind", ["pull", "push"])
def test_connection_refused(kind, aws, capsys):
    with socket.socket() as s:  # a port on 127.0.0.1 where nothing listens once the socket is closed
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    aws.setenv("AWS_ACCESS_KEY_ID", "testing")
    aws.setenv("AWS_SECRET_ACCESS_KEY", "testing")
    # botocore retries a refused connection with back-off (about 6-10 s here); one attempt keeps the test short
    endpoint(aws, f"http://127.0.0.1:{port}", config_kwargs={"retries": {"max_attempts": 1}})
    url = "s3://nsl-unreachable/grasp"
    assert run_cli(*attempt(kind, url)) == 2
    line = one_line(capsys)
    assert f"remote {url}: cannot reach the store" in line and f"127.0.0.1:{port}" in line
    assert "check the network" in line and "endpoint" in line
