"""An fsspec remote: a folder on any file system fsspec reaches (S3, GCS, Azure, local, ...).

Credentials and endpoints come from fsspec's own configuration (for S3: the
AWS environment variables, ``~/.aws``, or ``~/.config/fsspec/s3.json`` with
``client_kwargs.endpoint_url``); nsl passes none and records none.

Writes to a local folder go to a temporary name and are renamed; object
stores (S3, GCS, Azure) make each object visible only when it is complete.
"""

from __future__ import annotations

import posixpath
import re
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import fsspec

from nsl.errors import ConfigError, EnvironmentSetupError, NslError, UnknownReferenceError

from .remotes import Location, json_object


class FsRemote:
    """Files under one fsspec URL; relative paths use ``/``."""

    def __init__(self, loc: Location):
        self.loc = loc
        self.url = loc.url
        try:
            self.fs, self.root = fsspec.core.url_to_fs(loc.url)
        except ImportError as e:
            raise EnvironmentSetupError(
                f"remote {loc.url}: its file system needs a package that is not installed "
                f"({e}); for S3 install nsl[s3] (s3fs)"
            ) from None
        except ValueError as e:
            raise ConfigError(f"remote {loc.url} is not a URL fsspec understands ({e})") from None
        self.root = self.root.rstrip("/")
        self.local = "file" in (self.fs.protocol if isinstance(self.fs.protocol, tuple) else (self.fs.protocol,))

    def path(self, rel: str) -> str:
        return posixpath.join(self.root, rel) if rel else self.root

    def _io(self, what: str, fn, *args: Any) -> Any:
        """``fn(*args)``; a store's failure becomes a one-line nsl error naming this remote and the fix.

        FileNotFoundError (a missing file) passes through for the caller to handle, unless the
        bucket itself does not exist.
        """
        try:
            return fn(*args)
        except NslError:
            raise
        except FileNotFoundError as e:
            if not self.local and _missing_bucket(e):
                raise self._missing_bucket(what) from None
            raise
        except Exception as e:  # noqa: BLE001 - classified below; anything not from the store is re-raised
            error = remote_error(self.url, what, e)
            if error is None:
                raise
            raise error from None

    def _missing_bucket(self, what: str) -> UnknownReferenceError:
        bucket = self.root.split("/", 1)[0]
        return UnknownReferenceError(
            f"remote {self.url}: bucket {bucket!r} does not exist (while {what}); check the "
            "URL, or create the bucket and push to it"
        )

    def read_bytes(self, rel: str) -> bytes | None:
        """A small file's bytes, or None when it does not exist."""
        try:
            return self._io(f"reading {rel}", self.fs.cat_file, self.path(rel))
        except FileNotFoundError:
            return None

    def read_json(self, rel: str) -> dict | None:
        data = self.read_bytes(rel)
        if data is None:
            return None
        return json_object(data, f"{self.url}: file {rel}")

    def sizes(self, rel_dir: str = "") -> dict[str, int]:
        """``{relative path: size}`` of every file under ``rel_dir`` (one listing)."""
        base = self.path(rel_dir)
        try:
            found = self._io(f"listing {rel_dir or '/'}", self.fs.find, base, None, False, True)
        except FileNotFoundError:
            return {}
        out = {}
        for p, info in found.items():
            if info.get("type", "file") != "file":
                continue
            rel = posixpath.relpath(self.fs._strip_protocol(p), self.fs._strip_protocol(base))
            out[rel] = int(info.get("size") or 0)
        return out

    def versions(self) -> list[int]:
        """The dataset versions ``vN/`` under the root that hold a ``manifest.json`` (ascending)."""
        try:
            entries = self._io("listing versions", self.fs.ls, self.root, False)
        except FileNotFoundError:
            return []
        out = []
        for e in entries:
            m = re.fullmatch(r"v(\d+)", posixpath.basename(e.rstrip("/")))
            if m and self._io("checking a version", self.fs.exists, posixpath.join(e, "manifest.json")):
                out.append(int(m[1]))
        return sorted(out)

    def fetch(self, rel: str, dest: Path) -> None:
        """Download ``rel`` to the local file ``dest``; FileNotFoundError if it is not there."""
        self._io(f"downloading {rel}", self.fs.get_file, self.path(rel), str(dest))

    def put(self, rel: str, source: Path | bytes) -> None:
        """Upload a local file or bytes to ``rel`` (via a temporary name on a local file system)."""
        target = self.path(rel)
        self._io(f"creating the folder of {rel}", self.fs.makedirs, posixpath.dirname(target), True)
        tmp = posixpath.join(posixpath.dirname(target), f".{posixpath.basename(target)}.{uuid.uuid4().hex[:8]}.tmp")
        dst = tmp if self.local else target
        if isinstance(source, (bytes, bytearray)):
            self._io(f"uploading {rel}", self.fs.pipe_file, dst, bytes(source))
        else:
            self._io(f"uploading {rel}", self.fs.put_file, str(source), dst)
        if self.local:
            self._io(f"renaming {rel} into place", self.fs.mv, tmp, target)


# ----------------------------------------------------------------- errors
# Exceptions of these libraries come from the store (its client, its HTTP stack); others are bugs and keep
# their traceback.
_STORE_MODULES = (
    "botocore",
    "aiobotocore",
    "boto3",
    "s3fs",
    "aiohttp",
    "urllib3",
    "requests",
    "gcsfs",
    "google",
    "adlfs",
    "azure",
    "fsspec",
    "ssl",
    "socket",
)
_NO_CREDENTIALS = (
    "NoCredentialsError",
    "PartialCredentialsError",
    "CredentialRetrievalError",
    "UnauthorizedSSOTokenError",
    "SSOTokenLoadError",
    "NoAuthTokenError",
    "DefaultCredentialsError",
    "ClientAuthenticationError",
)
_UNREACHABLE = (
    "EndpointConnectionError",
    "ConnectTimeoutError",
    "ReadTimeoutError",
    "ConnectionClosedError",
    "ProxyConnectionError",
    "SSLError",
    "ClientConnectorError",
    "ServerDisconnectedError",
    "ServerTimeoutError",
    "ClientOSError",
    "ServiceRequestError",
)


def _names(e: BaseException) -> set[str]:
    return {c.__name__ for c in type(e).__mro__}


def _chain(e: BaseException) -> Iterator[BaseException]:
    """``e`` and the exceptions it was raised from or while handling."""
    seen = set()
    x: BaseException | None = e
    while x is not None and id(x) not in seen:
        seen.add(id(x))
        yield x
        x = x.__cause__ or x.__context__


def _code(e: BaseException) -> str | None:
    """An S3-style error code (``AccessDenied``, ``NoSuchBucket``, ...) anywhere in ``e``'s chain."""
    for x in _chain(e):
        response = getattr(x, "response", None)
        if isinstance(response, dict):
            code = (response.get("Error") or {}).get("Code")
            if code:
                return str(code)
    return None


def _missing_bucket(e: FileNotFoundError) -> bool:
    return _code(e) == "NoSuchBucket" or "bucket does not exist" in str(e).lower()


def _first_line(e: BaseException) -> str:
    text = str(e).strip()
    return text.splitlines()[0] if text else type(e).__name__


def _credentials_hint(url: str) -> str:
    if url.startswith(("s3://", "s3a://")):
        return "set AWS_ACCESS_KEY_ID and AWS_SECRET_ACCESS_KEY, or AWS_PROFILE with a profile in ~/.aws/credentials"
    return "configure the store's credentials (fsspec's configuration, or the store's usual place)"


def remote_error(url: str, what: str, e: BaseException) -> NslError | None:
    """The one-line nsl error for a store's failure ``e`` while doing ``what`` on remote ``url``.

    None when ``e`` is not a store's failure (a bug), which the caller re-raises as it is.
    """
    names = set().union(*(_names(x) for x in _chain(e)))
    detail = f"{type(e).__name__}: {_first_line(e)}"
    if names & set(_NO_CREDENTIALS):
        return EnvironmentSetupError(
            f"remote {url}: no credentials for the store (while {what}: {detail}); "
            f"{_credentials_hint(url)}, then run the command again"
        )
    if isinstance(e, PermissionError) or _code(e) in (
        "AccessDenied",
        "InvalidAccessKeyId",
        "SignatureDoesNotMatch",
        "ExpiredToken",
        "AllAccessDisabled",
    ):
        if url.startswith("file://"):
            return ConfigError(
                f"remote {url}: permission denied while {what} ({_first_line(e)}); check the folder's permissions"
            )
        return ConfigError(
            f"remote {url}: permission denied while {what} ({_first_line(e)}); use credentials "
            f"this remote grants access to ({_credentials_hint(url)}), or ask its owner for access"
        )
    if names & set(_UNREACHABLE) or any(isinstance(x, (ConnectionError, TimeoutError)) for x in _chain(e)):
        return EnvironmentSetupError(
            f"remote {url}: cannot reach the store while {what} ({detail}); check the "
            "network and the store's endpoint (for S3: AWS_ENDPOINT_URL or fsspec's "
            "s3 client_kwargs.endpoint_url), then run the command again"
        )
    from_store = any(type(x).__module__.split(".")[0] in _STORE_MODULES for x in _chain(e))
    if isinstance(e, OSError) or from_store:
        return ConfigError(
            f"remote {url}: {what} failed ({detail}); check the URL and the store's configuration, "
            "then run the command again"
        )
    return None
