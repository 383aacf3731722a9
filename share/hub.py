"""A Hugging Face Hub repository as a remote, through ``huggingface_hub``.

Uploads are one commit per push (``HfApi.create_commit``) holding only the
files whose sha256 differs from the manifest at the head of ``main``;
versions are tags (``HfApi.create_tag``); downloads are ``hf_hub_download``
at a fixed commit, one file at a time, so a pull can skip files it already
has.  The token is whatever ``huggingface_hub`` finds (``HF_TOKEN`` or a
prior ``hf auth login``); nsl never reads, prints or stores it.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

from huggingface_hub import CommitOperationAdd, CommitOperationDelete, HfApi, hf_hub_download
from huggingface_hub.errors import (
    EntryNotFoundError,
    GatedRepoError,
    HfHubHTTPError,
    LocalEntryNotFoundError,
    RepositoryNotFoundError,
    RevisionNotFoundError,
)

from nsl.errors import ConfigError, UnknownReferenceError

from .remotes import Location, json_object

SHA_RE = re.compile(r"[0-9a-f]{40}")


class HubRemote:
    """One Hub repository (dataset or model)."""

    def __init__(self, loc: Location):
        self.loc = loc
        self.url = loc.url
        self.repo_id = loc.repo_id
        self.repo_type = loc.repo_type
        self.api = HfApi()

    def _fail(self, what: str, e: Exception) -> Exception:
        """A one-line nsl error for a Hub failure (the Hub's messages carry no token)."""
        status = getattr(getattr(e, "response", None), "status_code", None)
        if isinstance(e, (RepositoryNotFoundError, GatedRepoError)) or status in (401, 403):
            return UnknownReferenceError(
                f"{self.url}: {what} failed: the repository does not exist or this account may not access it "
                "(log in with `hf auth login` or set HF_TOKEN)"
            )
        if isinstance(e, RevisionNotFoundError):
            return UnknownReferenceError(f"{self.url}: {what} failed: no such revision")
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        return ConfigError(f"{self.url}: {what} failed ({first}); check the network and run the command again")

    # --------------------------------------------------------------- refs
    def create_repo(self) -> None:
        try:
            self.api.create_repo(self.repo_id, repo_type=self.repo_type, exist_ok=True)
        except (HfHubHTTPError, OSError) as e:
            raise self._fail("creating the repository", e) from None

    def refs(self) -> tuple[dict[str, str], dict[str, str]]:
        """``({branch: commit}, {tag: commit})``."""
        try:
            refs = self.api.list_repo_refs(self.repo_id, repo_type=self.repo_type)
        except (HfHubHTTPError, OSError) as e:
            raise self._fail("listing revisions", e) from None
        return ({b.name: b.target_commit for b in refs.branches}, {t.name: t.target_commit for t in refs.tags})

    def commit_of(self, revision: str, branches: dict[str, str], tags: dict[str, str]) -> str:
        """The commit a tag, branch or commit id names; unknown ones list what exists."""
        if revision in tags:
            return tags[revision]
        if revision in branches:
            return branches[revision]
        if SHA_RE.fullmatch(revision):
            return revision
        known = ", ".join(sorted(tags) + sorted(branches)) or "none"
        raise UnknownReferenceError(f"{self.url} has no revision {revision!r}; its tags and branches: {known}")

    def tag(self, tag: str, commit: str, move: bool = False) -> None:
        """Point ``tag`` at ``commit`` (``move``: replace an existing tag of that name)."""
        try:
            if move:
                try:
                    self.api.delete_tag(self.repo_id, tag=tag, repo_type=self.repo_type)
                except RevisionNotFoundError:
                    pass
            self.api.create_tag(self.repo_id, tag=tag, revision=commit, repo_type=self.repo_type)
        except (HfHubHTTPError, OSError) as e:
            raise self._fail(f"tagging {tag}", e) from None

    # ------------------------------------------------------------ content
    def _download(self, rel: str, revision: str, into: Path) -> Path:
        return Path(
            hf_hub_download(self.repo_id, rel, repo_type=self.repo_type, revision=revision, local_dir=str(into))
        )

    def read_json(self, rel: str, revision: str) -> dict | None:
        """A small JSON file at ``revision``, or None when the file is not there."""
        with tempfile.TemporaryDirectory(prefix="nsl-hub-") as tmp:
            try:
                path = self._download(rel, revision, Path(tmp))
            except LocalEntryNotFoundError as e:  # offline: not the same as "the file is not there"
                raise self._fail(f"reading {rel}", e) from None
            except EntryNotFoundError:
                return None
            except (HfHubHTTPError, OSError) as e:
                raise self._fail(f"reading {rel}", e) from None
            data = Path(path).read_bytes()
        return json_object(data, f"{self.url}: file {rel} at {revision[:12]}")

    def fetch(self, rel: str, dest: Path, revision: str) -> None:
        """Download ``rel`` at ``revision`` to the local file ``dest``; FileNotFoundError if absent."""
        incoming = Path(dest).parent / f".{Path(dest).name}.incoming.tmp"
        try:
            path = self._download(rel, revision, incoming)
            os.replace(path, dest)
        except LocalEntryNotFoundError as e:
            raise self._fail(f"downloading {rel}", e) from None
        except EntryNotFoundError:
            raise FileNotFoundError(rel) from None
        except HfHubHTTPError as e:
            raise self._fail(f"downloading {rel}", e) from None
        except OSError as e:
            if isinstance(e, FileNotFoundError):
                raise
            raise self._fail(f"downloading {rel}", e) from None
        finally:
            shutil.rmtree(incoming, ignore_errors=True)

    def commit(self, files: dict[str, Path | bytes], delete: list[str], message: str) -> str:
        """One commit on ``main`` adding ``files`` and deleting ``delete``; returns its id."""
        ops = [
            CommitOperationAdd(path_in_repo=rel, path_or_fileobj=src if isinstance(src, bytes) else str(src))
            for rel, src in sorted(files.items())
        ]
        ops += [CommitOperationDelete(path_in_repo=rel) for rel in sorted(delete)]
        try:
            info = self.api.create_commit(
                self.repo_id, ops, commit_message=message, repo_type=self.repo_type, revision="main"
            )
        except (HfHubHTTPError, OSError) as e:
            raise self._fail("uploading", e) from None
        return info.oid
