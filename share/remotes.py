"""Remote addresses: the Hugging Face Hub or any fsspec URL, with an optional ``@REVISION``.

Accepted forms::

    hf://datasets/OWNER/NAME[@REV]     a dataset repository (REV: a tag such as v2, a branch, a commit)
    hf://OWNER/NAME[@REV]              a model repository (also hf://models/OWNER/NAME)
    s3://bucket/prefix[@vN]            any fsspec URL: gs://, az://, file:///abs/path, memory://, ...
    /a/local/path[@vN], ./relative     a plain path is a local folder

The revision is split off at the last ``@`` when what follows contains no
``/`` (so ``@`` inside a folder name is kept).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from nsl.errors import ConfigError

HUB_SCHEME = "hf://"
REPO_PART = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


@dataclass(frozen=True)
class Location:
    """A parsed remote address."""

    url: str  # the address without the revision (normalised: plain paths become file:// URLs)
    revision: str | None = None  # what follows '@', if anything
    repo_id: str | None = None  # Hub only: OWNER/NAME
    repo_type: str | None = None  # Hub only: "dataset" or "model"

    @property
    def is_hub(self) -> bool:
        return self.repo_id is not None

    @property
    def name(self) -> str:
        """The last path component that is not a version folder: a default local name."""
        parts = [p for p in self.url.split("://", 1)[-1].split("/") if p]
        while len(parts) > 1 and re.fullmatch(r"v\d+", parts[-1]):
            parts.pop()
        return parts[-1] if parts else ""

    def __str__(self) -> str:
        return self.url + (f"@{self.revision}" if self.revision else "")


def json_object(data: str | bytes, where: str) -> dict:
    """A remote JSON file's object; ``where`` names the file in the one-line error for damaged content."""
    import json

    from nsl.errors import CorruptDataError

    try:
        out = json.loads(data)
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise CorruptDataError(f"{where} is not valid JSON; the remote is damaged, push it again") from None
    if not isinstance(out, dict):
        raise CorruptDataError(f"{where} does not hold a JSON object; push it again")
    return out


def parse_remote(text: str) -> Location:
    """Parse a remote address (see the module docstring); malformed ones raise ConfigError."""
    if not isinstance(text, str) or not text.strip():
        raise ConfigError(
            f"remote {text!r} is empty; give hf://datasets/OWNER/NAME, hf://OWNER/NAME, "
            "s3://bucket/prefix or a folder path"
        )
    text = text.strip()
    base, at, rev = text.rpartition("@")
    if at and rev and "/" not in rev and base:
        text, revision = base, rev
    else:
        revision = None
    if text.startswith(HUB_SCHEME):
        return _hub(text, revision)
    if "://" not in text:
        text = "file://" + os.path.abspath(os.path.expanduser(text))
    elif "@" in text.split("://", 1)[1].split("/", 1)[0]:
        raise ConfigError(
            f"remote {text.split('://', 1)[0]}://... carries credentials in the URL; put them in "
            "fsspec's configuration or the store's usual place (e.g. AWS_PROFILE) instead"
        )
    return Location(text.rstrip("/") or text, revision)


def _hub(text: str, revision: str | None) -> Location:
    parts = [p for p in text[len(HUB_SCHEME) :].split("/") if p]
    repo_type = "model"
    if parts and parts[0] in ("datasets", "models", "spaces"):
        kind = parts.pop(0)
        if kind == "spaces":
            raise ConfigError(
                f"remote {text!r} is a Space; nsl pushes to dataset and model repositories "
                "(hf://datasets/OWNER/NAME or hf://OWNER/NAME)"
            )
        repo_type = "dataset" if kind == "datasets" else "model"
    if len(parts) != 2 or not all(REPO_PART.match(p) for p in parts):
        raise ConfigError(
            f"remote {text!r} is not a Hub repository; write hf://datasets/OWNER/NAME for a "
            "dataset or hf://OWNER/NAME for a model"
        )
    repo_id = "/".join(parts)
    url = f"{HUB_SCHEME}{'datasets/' if repo_type == 'dataset' else ''}{repo_id}"
    return Location(url, revision, repo_id, repo_type)
