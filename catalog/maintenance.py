"""Keeping the catalog and the workspace in step: ``rm``, ``gc`` and ``verify``.

- :func:`remove` deletes one catalog entry (then its files, if they live in
  the workspace).  It refuses while other entries depend on it: a checkpoint
  with child checkpoints, evaluations or tags; a dataset that checkpoints
  were trained on.  ``force=True`` removes it anyway, with its evaluations
  and tags; children keep their parent id and show it as removed.
- :func:`gc_plan` lists what no catalog entry references: checkpoint folders
  under ``checkpoints/`` that are not registered, and stale temporary files
  and folders (``.tmp-*``, ``.*.tmp``) left by interrupted writes.  Anything
  touched within ``min_age`` seconds is left alone, because a running process
  may be writing it, and so is everything in a folder whose writer lock
  (:mod:`nsl.locks`) a process holds.  Dataset versions are never collected: their folders
  are the datasets' own record (and ``NAME/.staging`` is a resumable
  collection).  :func:`gc_apply` deletes a plan.
- :func:`verify` re-hashes registered files and reports each one that is
  missing, altered or added since registration.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from nsl import workspace
from nsl.errors import ConfigError, NslError
from nsl.locks import dataset_lock, holder, is_lock_name

from .folders import WEIGHTS_FILE, file_sha256, hash_tree, is_temp_name
from .records import DATA_PREFIX, CheckpointEntry, DatasetEntry, parse_data_ref, short_hash
from .schema import utc_now

if TYPE_CHECKING:
    from .store import Catalog

GC_MIN_AGE_S = 3600.0  # default: leave alone anything modified within the last hour


def _inside(path: Path, root: Path) -> bool:
    try:
        Path(path).resolve().relative_to(Path(root).resolve())
        return True
    except ValueError:
        return False


def _delete(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()


# ------------------------------------------------------------------- remove
def checkpoint_dependents(cat: Catalog, entry: CheckpointEntry) -> list[str]:
    """What depends on a checkpoint, one description per kind (empty: free to remove)."""
    out = []
    kids = cat.children(entry.id)
    if kids:
        out.append(
            f"{len(kids)} child checkpoint(s) ({', '.join(k.ref for k in kids[:4])}{', ...' if len(kids) > 4 else ''})"
        )
    evals = cat.evaluations(entry.id)
    if evals:
        out.append(f"{len(evals)} evaluation(s)")
    tags = cat.tags(entry.id)
    if tags:
        out.append(f"tag(s) {', '.join(tags)}")
    return out


def remove(cat: Catalog, ref: str, force: bool = False, delete_files: bool = True) -> list[str]:
    """Remove the entry ``ref`` (``ckpt:...`` or ``data:NAME@vN``); returns what was removed."""
    if ref.strip().startswith(DATA_PREFIX):
        d = parse_data_ref(ref)
        if d.version is None:
            raise ConfigError(f"say which version to remove, e.g. {DATA_PREFIX}{d.name}@v1")
        return _remove_dataset(cat, cat.dataset(d.name, d.version), force, delete_files)
    return _remove_checkpoint(cat, cat.checkpoint(ref), force, delete_files)


def _remove_checkpoint(cat: Catalog, entry: CheckpointEntry, force: bool, delete_files: bool) -> list[str]:
    deps = checkpoint_dependents(cat, entry)
    if deps and not force:
        raise ConfigError(
            f"ckpt:{entry.ref} ({entry.short_id}) has dependents: {'; '.join(deps)}; remove those "
            "first, or pass --force (children then show their parent as removed)"
        )
    removed = [f"checkpoint {entry.ref} ({entry.short_id})"]
    with cat.write() as c:
        n = c.execute("DELETE FROM evaluations WHERE checkpoint = ?", (entry.id,)).rowcount
        for tag in cat.tags(entry.id):
            c.execute("INSERT INTO tags (tag, checkpoint, created) VALUES (?, NULL, ?)", (tag, utc_now()))
            removed.append(f"tag {tag}")
        c.execute("DELETE FROM checkpoint_data WHERE checkpoint = ?", (entry.id,))
        c.execute("DELETE FROM checkpoint_names WHERE checkpoint = ?", (entry.id,))
        c.execute("DELETE FROM checkpoints WHERE id = ?", (entry.id,))
    if n:
        removed.append(f"{n} evaluation(s)")
    folder = Path(entry.path)
    if delete_files and folder.exists() and _inside(folder, workspace.checkpoints_dir()):
        _delete(folder)
        removed.append(f"folder {folder}")
    return removed


def _remove_dataset(cat: Catalog, entry: DatasetEntry, force: bool, delete_files: bool) -> list[str]:
    users = cat.trained_on(entry.name, entry.version)
    if users and not force:
        shown = ", ".join(c.ref for c in users[:4]) + (", ..." if len(users) > 4 else "")
        raise ConfigError(
            f"data:{entry.ref} was used to train {len(users)} checkpoint(s) ({shown}); remove "
            "those first, or pass --force (their lineage then shows the dataset as removed)"
        )
    path = Path(entry.path)
    ours = delete_files and path.exists() and _inside(path, workspace.datasets_dir())
    with dataset_lock(entry.name) if ours else contextlib.nullcontext():  # not while a collection appends to it
        with cat.write() as c:
            c.execute("DELETE FROM datasets WHERE name = ? AND version = ?", (entry.name, entry.version))
        removed = [f"dataset {entry.ref}"]
        if ours:
            _delete(path)
            removed.append(f"folder {path}")
    return removed


# ----------------------------------------------------------------------- gc
@dataclass(frozen=True)
class GcItem:
    path: Path
    reason: str  # "unregistered checkpoint folder", "stale temporary file" or "stale temporary folder"
    size: int  # bytes


def _newest_mtime(path: Path) -> float:
    newest = path.lstat().st_mtime
    if path.is_dir() and not path.is_symlink():
        for dirpath, dirnames, filenames in os.walk(path):
            for n in dirnames + filenames:
                try:
                    newest = max(newest, os.lstat(os.path.join(dirpath, n)).st_mtime)
                except OSError:
                    pass
    return newest


def _size(path: Path) -> int:
    if path.is_file() or path.is_symlink():
        return path.lstat().st_size
    return sum(os.lstat(os.path.join(d, f)).st_size for d, _, fs in os.walk(path) for f in fs)


def gc_plan(cat: Catalog, min_age: float = GC_MIN_AGE_S) -> list[GcItem]:
    """What ``gc`` would delete; nothing is touched."""
    if min_age < 0:
        raise ConfigError(f"min_age {min_age!r} must be >= 0 seconds")
    home = workspace.home().resolve()
    ckpt_paths = {Path(c.path).resolve() for c in cat.checkpoints()}
    cutoff = time.time() - min_age
    found: dict[Path, str] = {}

    ckroot = workspace.checkpoints_dir().resolve()
    if ckroot.is_dir():
        for dirpath, dirnames, _ in os.walk(ckroot):
            keep = []
            for d in sorted(dirnames):
                p = Path(dirpath, d)
                if p.resolve() in ckpt_paths or is_temp_name(d):
                    continue  # registered (kept) or temporary (found by the temp scan below)
                if (p / WEIGHTS_FILE).exists():
                    found[p] = "unregistered checkpoint folder"
                else:
                    keep.append(d)
            dirnames[:] = keep
    skip = {workspace.cache_dir().resolve()}
    for dirpath, dirnames, filenames in os.walk(home):
        if Path(dirpath).resolve() in skip or holder(Path(dirpath)) is not None:  # a writer is at work there
            dirnames[:] = []
            continue
        for n in sorted(dirnames + filenames):
            p = Path(dirpath, n)
            if is_temp_name(n) and not is_lock_name(n) and p not in found:
                found[p] = "stale temporary " + ("folder" if p.is_dir() else "file")
        dirnames[:] = [d for d in dirnames if not is_temp_name(d) and Path(dirpath, d) not in found]
    return [GcItem(p, reason, _size(p)) for p, reason in sorted(found.items()) if _newest_mtime(p) <= cutoff]


def gc_apply(items: Iterable[GcItem]) -> int:
    """Delete the planned items (and checkpoint name folders left empty); returns bytes freed."""
    freed = 0
    ckroot = workspace.checkpoints_dir().resolve()
    for item in items:
        if not item.path.exists() and not item.path.is_symlink():
            continue
        _delete(item.path)
        freed += item.size
        parent = item.path.parent
        if parent.resolve() != ckroot and _inside(parent, ckroot) and parent.is_dir() and not any(parent.iterdir()):
            parent.rmdir()
    return freed


# ------------------------------------------------------------------- verify
@dataclass(frozen=True)
class Problem:
    ref: str  # "ckpt:NAME@STEP" or "data:NAME@vN"
    path: str
    detail: str  # "missing", "altered (...)", "added since registration", ...

    def __str__(self) -> str:
        return f"{self.ref}: {self.path}: {self.detail}"


@dataclass
class VerifyReport:
    checkpoints: int = 0
    datasets: int = 0
    problems: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems


def _compare(
    ref: str, root: Path, recorded: dict[str, str], actual: dict[str, str] | None, allow_extra: bool
) -> list[Problem]:
    if not root.exists():
        return [Problem(ref, str(root), "missing (the whole folder)")]
    out = []
    for rel, digest in sorted(recorded.items()):
        path = root / rel if root.is_dir() else root
        if actual is None:
            now = file_sha256(path) if path.is_file() else None
        else:
            now = actual.get(rel)
        if now is None:
            out.append(Problem(ref, str(path), "missing"))
        elif now != digest:
            out.append(Problem(ref, str(path), f"altered (sha256 {now[:12]}, registered {digest[:12]})"))
    if not allow_extra and actual is not None:
        for rel in sorted(set(actual) - set(recorded)):
            out.append(Problem(ref, str(root / rel), "added since registration"))
    return out


def verify(
    cat: Catalog, refs: Sequence[str] = (), dataset_hasher: Callable[[Path], str] | None = None, progress: bool = False
) -> VerifyReport:
    """Re-hash the files of the given entries (default: all) against their registration.

    Checkpoints: ``model.safetensors`` and ``config.json`` (the files the id
    covers).  Datasets: every file present at registration, plus files added
    since.  ``dataset_hasher(path) -> hash``, if given, recomputes the
    datasets' own manifest hash and compares it with the registered one.
    """
    from nsl.progress import progress_bar

    ckpts, datas = [], []
    for ref in refs:
        if ref.strip().startswith(DATA_PREFIX):
            d = parse_data_ref(ref)
            if d.version is not None:
                datas.append(cat.dataset(d.name, d.version))
            else:
                cat.dataset(d.name)  # raises for an unknown name, with near matches
                datas += cat.datasets(d.name)
        else:
            ckpts.append(cat.checkpoint(ref))
    if not refs:
        ckpts, datas = cat.checkpoints(), cat.datasets()
    report = VerifyReport()
    work = [(True, c) for c in ckpts] + [(False, d) for d in datas]
    for is_ckpt, e in progress_bar(work, desc="verify", unit="entry", disable=not progress):
        if is_ckpt:
            report.checkpoints += 1
            report.problems += _compare(f"ckpt:{e.ref}", Path(e.path), e.files, None, allow_extra=True)
        else:
            report.datasets += 1
            root = Path(e.path)
            problems = _compare(
                f"data:{e.ref}", root, e.files, hash_tree(root) if root.exists() else None, allow_extra=False
            )
            if dataset_hasher is not None and root.exists():
                try:
                    h = dataset_hasher(root)
                except NslError as err:  # a hasher that checks its own manifest raises on the first bad file
                    h, problems = e.hash, [*problems, Problem(f"data:{e.ref}", str(root), str(err))]
                if h != e.hash:
                    detail = f"content hash {short_hash(h)} differs from the registered {short_hash(e.hash)}"
                    problems.append(Problem(f"data:{e.ref}", str(root), detail))
            report.problems += problems
    return report
