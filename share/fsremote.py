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
from pathlib import Path
from typing import Any

import fsspec

from nsl.errors import ConfigError, EnvironmentSetupError, NslError

from .remotes import Location, json_object


class FsRemote:
    """Files under one fsspec URL; relative paths use ``/``."""

    def __init__(self, loc: Location):
        self.loc = loc
        self.url = loc.url
        try:
            self.fs, self.root = fsspec.core.url_to_fs(loc.url)
        except ImportError as e:
            raise EnvironmentSetupError(f"remote {loc.url}: its file system needs a package that is not installed "
                                        f"({e}); for S3 install nsl[s3] (s3fs)") from None
        except ValueError as e:
            raise ConfigError(f"remote {loc.url} is not a URL fsspec understands ({e})") from None
        self.root = self.root.rstrip("/")
        self.local = "file" in (self.fs.protocol if isinstance(self.fs.protocol, tuple) else (self.fs.protocol,))

    def path(self, rel: str) -> str:
        return posixpath.join(self.root, rel) if rel else self.root

    def _io(self, what: str, fn, *args: Any) -> Any:
        try:
            return fn(*args)
        except FileNotFoundError:
            raise
        except NslError:
            raise
        except PermissionError as e:
            raise ConfigError(f"{self.url}: permission denied while {what} ({e}); check the store's credentials "
                              "(fsspec configuration, e.g. AWS_PROFILE)") from None
        except OSError as e:
            raise ConfigError(f"{self.url}: {what} failed ({type(e).__name__}: {e}); check the URL and the "
                              "store's configuration, then run the command again") from None

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
