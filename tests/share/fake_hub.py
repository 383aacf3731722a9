"""A local stand-in for the Hugging Face Hub at the ``huggingface_hub`` boundary.

Repositories are lists of commits (each a full ``{path: bytes}`` snapshot),
with branches and tags.  ``FakeHfApi`` implements the ``HfApi`` methods nsl
and lerobot call; ``download`` and ``snapshot`` stand in for
``hf_hub_download`` and ``snapshot_download``.  Every upload and download is
recorded, so tests can assert exactly which files and revisions moved.
"""

from __future__ import annotations

import fnmatch
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

from huggingface_hub import CommitOperationAdd, CommitOperationDelete
from huggingface_hub.errors import EntryNotFoundError, RepositoryNotFoundError, RevisionNotFoundError
from huggingface_hub.hf_api import GitRefInfo, GitRefs


@dataclass
class Repo:
    commits: dict[str, dict[str, bytes]] = field(default_factory=dict)
    branches: dict[str, str] = field(default_factory=dict)
    tags: dict[str, str] = field(default_factory=dict)


class FakeHub:
    def __init__(self):
        self.repos: dict[tuple[str, str], Repo] = {}
        self.uploads: list[tuple[str, str, list[str]]] = []  # (repo_id, parent branch, paths added) per commit
        self.downloads: list[tuple[str, str, str]] = []  # (repo_id, filename, revision)
        self.fail_download = None  # optional callable(filename) raising, to inject faults

    def repo(self, repo_id: str, repo_type: str | None) -> Repo:
        key = (repo_type or "model", repo_id)
        if key not in self.repos:
            raise RepositoryNotFoundError(f"404 Client Error. Repository Not Found for url: {repo_id}")
        return self.repos[key]

    def snapshot_at(self, repo_id: str, repo_type: str | None, revision: str | None) -> dict[str, bytes]:
        r = self.repo(repo_id, repo_type)
        rev = revision or "main"
        sha = r.tags.get(rev) or r.branches.get(rev) or (rev if rev in r.commits else None)
        if sha is None:
            raise RevisionNotFoundError(f"404 Client Error. Revision Not Found for url: {repo_id}@{rev}")
        return r.commits[sha]

    # ------------------------------------------------ download functions
    def download(self, repo_id, filename, *, repo_type=None, revision=None, local_dir=None, **kw) -> str:
        files = self.snapshot_at(repo_id, repo_type, revision)
        self.downloads.append((repo_id, filename, revision))
        if self.fail_download is not None:
            self.fail_download(filename)
        if filename not in files:
            raise EntryNotFoundError(f"404 Client Error. Entry Not Found for url: {repo_id}/{filename}")
        out = Path(local_dir) / filename
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(files[filename])
        return str(out)

    def snapshot(
        self, repo_id, *, repo_type=None, revision=None, local_dir=None, allow_patterns=None, ignore_patterns=None, **kw
    ) -> str:
        files = self.snapshot_at(repo_id, repo_type, revision)

        def match(path: str, patterns) -> bool:
            pats = [patterns] if isinstance(patterns, str) else list(patterns)
            return any(fnmatch.fnmatch(path, p) or (p.endswith("/") and path.startswith(p)) for p in pats)

        for path, data in files.items():
            if allow_patterns is not None and not match(path, allow_patterns):
                continue
            if ignore_patterns is not None and match(path, ignore_patterns):
                continue
            self.downloads.append((repo_id, path, revision))
            out = Path(local_dir) / path
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_bytes(data)
        return str(local_dir)


class FakeHfApi:
    """The ``HfApi`` methods used by nsl and by lerobot's hub loading, backed by a :class:`FakeHub`."""

    def __init__(self, hub: FakeHub):
        self.hub = hub

    def create_repo(self, repo_id, *, repo_type=None, exist_ok=False, private=False, **kw):
        key = (repo_type or "model", repo_id)
        if key in self.hub.repos and not exist_ok:
            raise ValueError(f"repo {repo_id} exists")
        self.hub.repos.setdefault(key, Repo())
        return SimpleNamespace(repo_id=repo_id)

    def list_repo_refs(self, repo_id, *, repo_type=None, **kw) -> GitRefs:
        r = self.hub.repo(repo_id, repo_type)
        return GitRefs(
            branches=[GitRefInfo(n, f"refs/heads/{n}", c) for n, c in r.branches.items()],
            converts=[],
            tags=[GitRefInfo(n, f"refs/tags/{n}", c) for n, c in r.tags.items()],
        )

    def create_commit(self, repo_id, operations, *, commit_message, repo_type=None, revision=None, **kw):
        r = self.hub.repo(repo_id, repo_type)
        branch = revision or "main"
        parent = r.branches.get(branch)
        files = dict(r.commits[parent]) if parent else {}
        added = []
        for op in operations:
            if isinstance(op, CommitOperationAdd):
                src = op.path_or_fileobj
                files[op.path_in_repo] = src if isinstance(src, bytes) else Path(src).read_bytes()
                added.append(op.path_in_repo)
            elif isinstance(op, CommitOperationDelete):
                files.pop(op.path_in_repo, None)
        h = hashlib.sha1(f"{parent}\n{commit_message}\n".encode())
        for p in sorted(files):
            h.update(p.encode() + hashlib.sha256(files[p]).digest())
        sha = h.hexdigest()
        r.commits[sha] = files
        r.branches[branch] = sha
        self.hub.uploads.append((repo_id, branch, sorted(added)))
        return SimpleNamespace(oid=sha, commit_url=f"https://hub.invalid/{repo_id}/commit/{sha}")

    def create_tag(self, repo_id, *, tag, revision=None, repo_type=None, exist_ok=False, **kw):
        r = self.hub.repo(repo_id, repo_type)
        if tag in r.tags and not exist_ok:
            raise ValueError(f"409 Conflict: tag {tag} exists")
        rev = revision or "main"
        r.tags[tag] = r.branches.get(rev) or r.tags.get(rev) or rev

    def delete_tag(self, repo_id, *, tag, repo_type=None, **kw):
        r = self.hub.repo(repo_id, repo_type)
        if tag not in r.tags:
            raise RevisionNotFoundError(f"404 Client Error. Revision Not Found: {tag}")
        del r.tags[tag]
