"""Resumable, append-only writing of a dataset version through a staging area.

A collection writes episodes ``[start, stop)`` of dataset ``NAME`` into
``NAME/.staging/`` in complete files of ``episodes_per_file`` episodes (file
``n`` holds episodes ``[start + j*E, start + (j+1)*E)`` of this collection), each
renamed into place when complete.  Running the same collection again resumes
after the last complete file; the files do not depend on where it was
interrupted or how many workers produced the episodes, so a resumed collection
has the same hash as an uninterrupted one.

:meth:`Collection.finish` assembles the new version in a temporary directory
(hard links to the parent version's files, the staged files, fresh metadata),
hashes it and renames it to ``NAME/vN``.  A killed run leaves a staging area or
a temporary directory, never a partial ``vN``.

One process writes a dataset at a time: :meth:`Collection.begin` takes the
dataset's writer lock (:func:`nsl.locks.dataset_lock`, an OS lock that dies
with its holder) and the collection holds it until :meth:`Collection.close`
(or the end of its ``with`` block).  Everything in ``.staging`` and every
``.tmp-v*`` is therefore the holder's own, and :meth:`begin` clears what a
killed holder left only under the lock.
"""

from __future__ import annotations

import datetime as dt
import json
import os
import shutil
import tempfile
from collections.abc import Iterable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError
from nsl.locks import dataset_lock
from nsl.workspace import atomic_write_json

from . import layout, versions, writer
from . import stats as statslib
from .reader import DatasetVersion, open_version, read_episode_stats, read_parquet

PLAN_FILE = "plan.json"


def _content_spec(spec: dict[str, Any]) -> str:
    """The settings that define a collection's episodes, comparable as a string.

    A checkpoint policy is identified by its content id.  A checkpoint folder path, which older nsl versions
    recorded in the policy's description, does not define the episodes and is left out, so a dataset they
    collected can still be appended to, and a collection they staged resumed.
    """
    policy = {k: v for k, v in (spec.get("policy") or {}).items() if k != "checkpoint"}
    return json.dumps({**spec, "policy": policy}, sort_keys=True)


class Collection:
    """Episodes ``[start, stop)`` of ``name`` on their way to a new version."""

    def __init__(self, name: str, plan: dict[str, Any], parent: DatasetVersion | None, lock: ExitStack | None = None):
        self.name, self.plan, self.parent = name, plan, parent
        self.staging = versions.dataset_root(name) / layout.STAGING_DIR
        self._lock = lock  # holds the dataset's writer lock (from begin); None: a read-only look at a staging area
        self._buffer: list[Any] = []
        self._cursor: int | None = None  # episode index of the first buffered episode
        self._next_frame = 0  # global frame index of the first buffered episode

    # -- the writer lock --------------------------------------------------------------------------------------------

    def close(self) -> None:
        """Release the dataset's writer lock (idempotent); the staged files stay for a resume."""
        lock, self._lock = self._lock, None
        if lock is not None:
            lock.close()

    def __enter__(self) -> Collection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # a collection dropped without close() (an interrupted caller) lets go of the lock
        if getattr(self, "_lock", None) is not None:
            try:
                self.close()
            except Exception:  # interpreter shutdown: the OS releases the lock with the process
                pass

    def _check_writer(self) -> None:
        if self._lock is None:
            raise ConfigError(
                f"dataset {self.name}: this collection does not hold the dataset's writer lock; "
                "start it with Collection.begin"
            )

    # -- planning ---------------------------------------------------------------------------------------------------

    @classmethod
    def begin(
        cls,
        name: str,
        episodes: int,
        spec: dict[str, Any],
        image_size: int,
        episodes_per_file: int = layout.DEFAULT_EPISODES_PER_FILE,
        restart: bool = False,
        *,
        wait: bool = False,
    ) -> Collection:
        """Plan (or resume) growing ``name`` to ``episodes`` episodes collected under ``spec``.

        ``spec`` is the provenance that defines the content (environment, policy,
        seed); it must match the latest version's to append, and the staged
        plan's to resume.  Takes the dataset's writer lock first: while another
        process holds it, raise LockedError naming it, or with ``wait`` wait
        for it.  The collection holds the lock until :meth:`close`; use it as a
        context manager.
        """
        versions.check_name(name)
        if episodes < 1 or episodes_per_file < 1:
            raise ConfigError(f"episodes ({episodes}) and episodes per file ({episodes_per_file}) must be >= 1")
        lock = ExitStack()
        lock.enter_context(dataset_lock(name, wait=wait))
        try:
            return cls._plan(name, episodes, spec, image_size, episodes_per_file, restart, lock)
        except BaseException:
            lock.close()
            raise

    @classmethod
    def _plan(
        cls,
        name: str,
        episodes: int,
        spec: dict[str, Any],
        image_size: int,
        episodes_per_file: int,
        restart: bool,
        lock: ExitStack,
    ) -> Collection:
        """:meth:`begin` under the writer lock: the latest version, the staged plan and the clean-up are read and
        done only now, so they are never another writer's."""
        spec = json.loads(json.dumps(spec, sort_keys=True))  # compare as stored (tuples become lists)
        parent = open_version(name) if versions.list_versions(name) else None
        start = parent.num_episodes if parent else 0
        if parent is not None:
            last = parent.provenance["collections"][-1]
            if _content_spec(last["spec"]) != _content_spec(spec) or parent.image_size != image_size:
                raise ConfigError(
                    f"dataset {parent.ref} was collected with other settings ({_spec_summary(last['spec'])}, "
                    f"{parent.image_size}px); appending needs the same shift, engine, policy, seed and image size, "
                    f"or choose a new --dataset name"
                )
            episodes_per_file = int(parent.provenance.get("episodes_per_file", episodes_per_file))
        plan: dict[str, Any] = {
            "format": layout.NSL_FORMAT,
            "start": start,
            "stop": max(start, episodes),
            "episodes_per_file": episodes_per_file,
            "image_size": image_size,
            "spec": spec,
            "parent": parent.hash if parent else None,
            "first_file": _num_files(parent) if parent else 0,
        }
        staging = versions.dataset_root(name) / layout.STAGING_DIR
        for stale in versions.dataset_root(name).glob(".tmp-v*"):  # left by a holder killed while publishing
            shutil.rmtree(stale, ignore_errors=True)
        if restart and staging.exists():
            shutil.rmtree(staging)
        old = _load_plan(staging)
        if old is not None:
            same = {k: v for k, v in old.items() if k not in ("stop", "spec")} == {
                k: v for k, v in plan.items() if k not in ("stop", "spec")
            } and _content_spec(old["spec"]) == _content_spec(plan["spec"])
            if not same:
                raise ConfigError(
                    f"dataset {name} has an unfinished collection with other settings "
                    f"({_spec_summary(old['spec'])}, episodes {old['start']}..{old['stop']}); run that command "
                    "again to finish it, or add --restart to discard it"
                )
        if plan["stop"] > start:
            staging.mkdir(parents=True, exist_ok=True)
            atomic_write_json(staging / PLAN_FILE, plan)
        return cls(name, plan, parent, lock)

    @property
    def start(self) -> int:
        return self.plan["start"]

    @property
    def stop(self) -> int:
        return self.plan["stop"]

    def file_ranges(self) -> list[tuple[int, int, int]]:
        """(file number, first episode, stop episode) of every file this collection writes."""
        e, first = self.plan["episodes_per_file"], self.plan["first_file"]
        return [(first + j, a, min(a + e, self.stop)) for j, a in enumerate(range(self.start, self.stop, e))]

    def staged_files(self) -> list[tuple[int, int, int]]:
        """The complete staged files: the longest prefix of :meth:`file_ranges` on disk (read-only)."""
        done = []
        for n, a, b in self.file_ranges():
            data = self.staging / layout.data_path(n)
            eps = self.staging / layout.episodes_path(n)
            if not (data.is_file() and eps.is_file()):
                break
            rows = read_parquet(eps, columns=["episode_index"])["episode_index"].to_pylist()
            if rows != list(range(a, b)):  # a partial last file of an earlier, shorter plan
                break
            done.append((n, a, b))
        return done

    def missing_indices(self) -> list[int]:
        """Episode indices still to collect, in order (staged files after a gap or of another plan are removed)."""
        self._check_writer()
        staged = self.staged_files()
        for n, _, _ in self.file_ranges()[len(staged) :]:
            for p in (self.staging / layout.data_path(n), self.staging / layout.episodes_path(n)):
                p.unlink(missing_ok=True)
        first = staged[-1][2] if staged else self.start
        return list(range(first, self.stop))

    @property
    def up_to_date(self) -> bool:
        return self.stop <= self.start

    # -- writing ----------------------------------------------------------------------------------------------------

    def _frames_before(self, file_number: int) -> int:
        total = self.parent.num_frames if self.parent else 0
        for n, _, _ in self.file_ranges():
            if n >= file_number:
                break
            lengths = read_parquet(self.staging / layout.episodes_path(n), columns=["length"])["length"]
            total += sum(lengths.to_pylist())
        return total

    def add(self, episode: writer.EpisodeLike) -> bool:
        """Buffer the next episode (in index order); write a file when one is complete.  True if written."""
        self._check_writer()
        if self._cursor is None:  # first episode of this run: resume after the staged files
            missing = self.missing_indices()
            if not missing:
                raise ConfigError(f"dataset {self.name}: every episode of this collection is already staged")
            self._cursor = missing[0]
            self._next_frame = self._frames_before(self._file_of(self._cursor)[0])
        index = self._cursor + len(self._buffer)
        if index >= self.stop:
            raise ConfigError(f"dataset {self.name}: episode {index} is beyond this collection's {self.stop}")
        self._buffer.append(episode)
        n, a, b = self._file_of(index)
        if index + 1 < b:
            return False
        writer.write_file_pair(self.staging, n, self._buffer, a, self._next_frame, self.plan["image_size"])
        self._next_frame += sum(len(ep.actions) for ep in self._buffer)
        self._cursor, self._buffer = b, []
        return True

    def _file_of(self, index: int) -> tuple[int, int, int]:
        return next(r for r in self.file_ranges() if r[1] <= index < r[2])

    def finish(self, created: dict[str, Any] | None = None) -> DatasetVersion:
        """Publish the staged files (plus the parent's) as the next version of ``name`` (the lock stays held)."""
        self._check_writer()
        if self.up_to_date:
            raise ConfigError(f"dataset {self.name} has nothing new to publish")
        staged = self.staged_files()
        if len(staged) != len(self.file_ranges()):
            missing = self.missing_indices()
            raise ConfigError(
                f"dataset {self.name}: episodes {missing[0]}..{missing[-1]} are not collected yet; "
                "run the collection again to finish it"
            )
        root = versions.dataset_root(self.name)
        version = (self.parent.version + 1) if self.parent else 1
        tmp = Path(tempfile.mkdtemp(prefix=f".tmp-v{version}-", dir=root))
        try:
            known: dict[str, dict[str, Any]] = {}
            if self.parent is not None:
                pm = self.parent.manifest
                versions.check_files(self.parent.root, pm, quick=True, label=self.parent.ref)
                for rel in pm["files"]:
                    if rel.startswith(("data/", "meta/episodes/")):
                        versions.link_or_copy(self.parent.root / rel, tmp / rel)
                known = versions.inode_table(self.parent.root, pm)
            for n, _, _ in staged:
                for rel in (layout.data_path(n), layout.episodes_path(n)):
                    (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
                    os.link(self.staging / rel, tmp / rel)
            self._write_meta(tmp)
            manifest = versions.build_manifest(tmp, known, created=self._created(version, created))
            final = versions.publish(tmp, self.name, version, manifest)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        shutil.rmtree(self.staging, ignore_errors=True)
        return DatasetVersion(self.name, version, final)

    def _write_meta(self, tmp: Path) -> None:
        provenance = {
            "format": layout.NSL_FORMAT,
            "image_size": self.plan["image_size"],
            "episodes_per_file": self.plan["episodes_per_file"],
            "collections": [
                *(self.parent.provenance["collections"] if self.parent else []),
                {"episodes": [self.start, self.stop], "spec": self.plan["spec"]},
            ],
        }
        # Episode stats and totals come from the (small) episode metadata files only.
        episode_files = [f for f in versions.content_files(tmp) if f.startswith("meta/episodes/")]
        per_episode = read_episode_stats(tmp, episode_files)
        total_frames = sum(int(s[next(iter(s))]["count"][0]) for s in per_episode)
        info = layout.DatasetInfo.new(self.plan["image_size"], len(per_episode), total_frames)
        writer.write_meta(tmp, info, statslib.aggregate(per_episode), provenance)

    def _created(self, version: int, extra: dict[str, Any] | None) -> dict[str, Any]:
        from nsl import __version__, code_version

        return {
            "name": self.name,
            "version": version,
            "parent": self.plan["parent"],
            "time": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "nsl_version": __version__,
            "code_version": code_version(),
            **(extra or {}),
        }


def _num_files(v: DatasetVersion) -> int:
    return len(v.episode_files())


def _load_plan(staging: Path) -> dict[str, Any] | None:
    try:
        return json.loads((staging / PLAN_FILE).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None


def _spec_summary(spec: dict[str, Any]) -> str:
    env = spec.get("env", {})
    engine = f", engine {env['engine']}" if "engine" in env else ""  # absent: mujoco, as before the option
    return f"shift {env.get('shift', '?')}{engine}, policy {spec.get('policy_ref', '?')}, seed {spec.get('seed', '?')}"


def unfinished() -> list[dict[str, Any]]:
    """Staged collections that have not been published yet (resume them by re-running their command)."""
    from nsl.workspace import datasets_dir

    out = []
    root = datasets_dir()
    for plan_path in sorted(root.glob(f"*/{layout.STAGING_DIR}/{PLAN_FILE}")) if root.is_dir() else []:
        plan = _load_plan(plan_path.parent)
        if plan is None:
            continue
        c = Collection(plan_path.parent.parent.name, plan, None)
        staged = sum(b - a for _, a, b in c.staged_files())
        out.append(
            {"name": c.name, "episodes": [c.start, c.stop], "staged": staged, "settings": _spec_summary(plan["spec"])}
        )
    return out


def write_dataset(
    name: str,
    episodes: Iterable[writer.EpisodeLike],
    spec: dict[str, Any],
    image_size: int,
    count: int,
    episodes_per_file: int = layout.DEFAULT_EPISODES_PER_FILE,
    created: dict[str, Any] | None = None,
) -> DatasetVersion:
    """Write ``count`` episodes (indices continue the latest version) as a new version of ``name``."""
    with dataset_lock(versions.check_name(name)):  # the latest version cannot change before begin (reentrant)
        latest = versions.list_versions(name)
        start = open_version(name).num_episodes if latest else 0
        with Collection.begin(name, start + count, spec, image_size, episodes_per_file, restart=True) as c:
            for ep in episodes:
                c.add(ep)
            return c.finish(created)
