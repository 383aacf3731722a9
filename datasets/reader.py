"""Reading dataset versions: metadata, episodes as arrays, and views (tiers, splits).

A :class:`DatasetView` is a run of consecutive episodes ``[start, stop)`` of one
version.  A tier ``NAME@vN:K`` is the view ``[0, K)``; a held-out split is a
view of the last episodes.  Views read only the Parquet row groups they need
(one row group per episode).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from nsl import keys
from nsl.errors import ConfigError, CorruptDataError

from . import layout, versions
from . import stats as statslib

NUMERIC_KEYS = (
    keys.OBS_STATE,
    keys.ACTION,
    keys.REWARD,
    keys.DONE,
    keys.SUCCESS,
    keys.TRUNCATED,
    keys.TIMESTAMP,
    keys.FRAME_INDEX,
    keys.EPISODE_INDEX,
    keys.INDEX,
    keys.TASK_INDEX,
)
_EP_COLUMNS = [
    "episode_index",
    "length",
    "data/chunk_index",
    "data/file_index",
    "dataset_from_index",
    "dataset_to_index",
    layout.EP_SUCCESS,
    layout.EP_TERMINATED,
    layout.EP_TRUNCATED,
    layout.EP_CONTENT_HASH,
]


def read_parquet(path: Path, columns: list[str] | None = None, row_groups: list[int] | None = None) -> pa.Table:
    """Read a Parquet file (or some of its row groups); damage becomes a CorruptDataError naming the file."""
    try:
        f = pq.ParquetFile(path)
        if row_groups is None:
            return f.read(columns=columns)
        return f.read_row_groups(row_groups, columns=columns)
    except FileNotFoundError:
        raise CorruptDataError(f"file {path} is missing; run `nsl dataset verify` on the version") from None
    except (pa.ArrowException, OSError, ValueError) as e:
        raise CorruptDataError(
            f"file {path} is damaged and cannot be read as Parquet "
            f"({str(e).splitlines()[0][:120]}); run `nsl dataset verify`"
        ) from None


def decode_png(data: bytes, path: Path | str = "") -> np.ndarray:
    """(H, W, 3) uint8 RGB pixels of PNG bytes."""
    import cv2

    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if img is None:
        raise CorruptDataError(f"file {path}: an embedded image cannot be decoded; run `nsl dataset verify`")
    if img.ndim == 2:
        return np.repeat(img[..., None], 3, axis=2)
    return np.ascontiguousarray(img[..., 2::-1])  # BGR(A) -> RGB


def read_episode_stats(root: Path, episode_files: list[str]) -> list[statslib.Stats]:
    """The per-episode stats stored in ``meta/episodes`` files, in order."""
    out: list[statslib.Stats] = []
    for f in sorted(episode_files):
        t = read_parquet(Path(root) / f)
        cols = [c for c in t.column_names if c.startswith("stats/")]
        out.extend(statslib.from_columns(r) for r in t.select(cols).to_pylist())
    return out


def column_array(col: pa.ChunkedArray | pa.Array) -> np.ndarray:
    """A numeric Arrow column (scalar or fixed-size list) as a numpy array."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_fixed_size_list(col.type) or pa.types.is_list(col.type):
        width = col.type.list_size if pa.types.is_fixed_size_list(col.type) else None
        flat = col.flatten().to_numpy(zero_copy_only=False)
        return flat.reshape(len(col), width if width is not None else -1)
    return col.to_numpy(zero_copy_only=False)


@dataclass(frozen=True)
class EpisodeTable:
    """Per-episode metadata of a version as arrays (from ``meta/episodes``)."""

    length: np.ndarray  # (E,) frames per episode
    start: np.ndarray  # (E,) global index of the first frame
    file_number: np.ndarray  # (E,) data file holding the episode
    row_group: np.ndarray  # (E,) row group of the episode in its file
    success: np.ndarray  # (E,) bool
    terminated: np.ndarray  # (E,) bool
    truncated: np.ndarray  # (E,) bool
    content_hash: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.length)


class DatasetVersion:
    """A published version: ``info``, ``manifest``, ``provenance`` and the episode table."""

    def __init__(self, name: str, version: int, root: Path):
        self.name, self.version, self.root = name, int(version), Path(root)
        self.manifest = versions.load_manifest(self.root)
        self.info = layout.DatasetInfo.load(self.root)
        try:
            self.provenance: dict[str, Any] = json.loads((self.root / layout.NSL_META_PATH).read_text())
        except (OSError, json.JSONDecodeError):
            raise CorruptDataError(
                f"file {self.root / layout.NSL_META_PATH} is missing or damaged; run `nsl dataset verify`"
            ) from None
        from nsl import plugins

        plugins.require(plugins.recorded(self.provenance), f"dataset {self.ref}")  # made with a plugin shift/policy

    @property
    def ref(self) -> str:
        return f"{self.name}@v{self.version}"

    @property
    def hash(self) -> str:
        return self.manifest["hash"]

    @property
    def num_episodes(self) -> int:
        return self.info.total_episodes

    @property
    def num_frames(self) -> int:
        return self.info.total_frames

    @property
    def image_size(self) -> int:
        return self.info.image_size

    def episode_files(self) -> list[str]:
        return sorted(f for f in self.manifest["files"] if f.startswith("meta/episodes/"))

    def data_file(self, file_number: int) -> str:
        return layout.data_path(int(file_number), self.info.chunks_size)

    @cached_property
    def episodes(self) -> EpisodeTable:
        tables = [read_parquet(self.root / f, columns=_EP_COLUMNS) for f in self.episode_files()]
        if not tables:
            raise CorruptDataError(f"{self.ref}: no episode metadata under {self.root / 'meta/episodes'}")
        t = pa.concat_tables(tables)
        get = {c: column_array(t[c]) for c in _EP_COLUMNS if c != layout.EP_CONTENT_HASH}
        n = len(t)
        file_number = get["data/chunk_index"] * self.info.chunks_size + get["data/file_index"]
        order = np.arange(n)
        first_of_file = np.r_[True, file_number[1:] != file_number[:-1]]
        group_start = np.maximum.accumulate(np.where(first_of_file, order, 0))
        ok = (
            n == self.num_episodes
            and np.array_equal(get["episode_index"], order)
            and np.array_equal(get["dataset_from_index"], np.r_[0, np.cumsum(get["length"])[:-1]])
            and int(get["length"].sum()) == self.num_frames
        )
        if not ok:
            raise CorruptDataError(
                f"{self.ref}: meta/episodes does not match meta/info.json "
                f"({n} episode rows, info says {self.num_episodes}); run `nsl dataset verify`"
            )
        return EpisodeTable(
            length=get["length"].astype(np.int64),
            start=get["dataset_from_index"].astype(np.int64),
            file_number=file_number.astype(np.int64),
            row_group=order - group_start,
            success=get[layout.EP_SUCCESS].astype(bool),
            terminated=get[layout.EP_TERMINATED].astype(bool),
            truncated=get[layout.EP_TRUNCATED].astype(bool),
            content_hash=tuple(t[layout.EP_CONTENT_HASH].to_pylist()),
        )

    def episode_stats(self) -> list[statslib.Stats]:
        """Per-episode stats (for pooling into ``meta/stats.json``)."""
        return read_episode_stats(self.root, self.episode_files())

    def view(self, start: int = 0, stop: int | None = None) -> DatasetView:
        return DatasetView(self, start, self.num_episodes if stop is None else stop)

    def describe(self) -> dict[str, Any]:
        ep = self.episodes
        return {
            "ref": self.ref,
            "name": self.name,
            "version": self.version,
            "hash": self.hash,
            "path": str(self.root),
            "episodes": self.num_episodes,
            "frames": self.num_frames,
            "success_rate": float(ep.success.mean()) if len(ep) else 0.0,
            "image_size": self.image_size,
            "provenance": self.provenance,
            "created": self.manifest.get("created", {}),
        }


class DatasetView:
    """Episodes ``[start, stop)`` of a version (a tier is ``[0, K)``)."""

    def __init__(self, version: DatasetVersion, start: int, stop: int):
        if not 0 <= start < stop <= version.num_episodes:
            raise ConfigError(
                f"{version.ref} has {version.num_episodes} episodes; the range [{start}, {stop}) "
                f"is not inside it (tiers go up to :{version.num_episodes})"
            )
        self.version, self.start, self.stop = version, int(start), int(stop)

    @property
    def ref(self) -> str:
        v = self.version
        if self.start == 0:
            return v.ref if self.stop == v.num_episodes else f"{v.ref}:{self.stop}"
        return f"{v.ref}[{self.start}:{self.stop}]"

    @property
    def num_episodes(self) -> int:
        return self.stop - self.start

    @property
    def frame_range(self) -> tuple[int, int]:
        """Global frame indices ``[first, last + 1)`` covered by the view."""
        ep = self.version.episodes
        return int(ep.start[self.start]), int(ep.start[self.stop - 1] + ep.length[self.stop - 1])

    @property
    def num_frames(self) -> int:
        a, b = self.frame_range
        return b - a

    @property
    def success_rate(self) -> float:
        return float(self.version.episodes.success[self.start : self.stop].mean())

    @property
    def content_hash(self) -> str:
        """Hash of the view's episodes only: a tier has the same hash in every version containing it."""
        return versions.tier_hash(list(self.version.episodes.content_hash[self.start : self.stop]))

    def data_files(self) -> list[str]:
        numbers = np.unique(self.version.episodes.file_number[self.start : self.stop])
        return [self.version.data_file(n) for n in numbers]

    def check(self, quick: bool = False) -> None:
        """Check the files this view reads against the manifest (CorruptDataError names a bad file)."""
        v = self.version
        files = [*self.data_files(), *v.episode_files(), layout.INFO_PATH, layout.NSL_META_PATH]
        versions.check_files(v.root, v.manifest, only=sorted(set(files)), quick=quick, label=v.ref)

    def _groups(self) -> Iterator[tuple[Path, list[int]]]:
        """(data file, row groups) pairs covering the view, in episode order."""
        ep = self.version.episodes
        numbers = ep.file_number[self.start : self.stop]
        groups = ep.row_group[self.start : self.stop]
        for n in np.unique(numbers):
            yield self.version.root / self.version.data_file(n), groups[numbers == n].tolist()

    def read_columns(self, columns: tuple[str, ...] = NUMERIC_KEYS) -> dict[str, np.ndarray]:
        """Numeric frame columns of the view (no images), concatenated in frame order."""
        parts: dict[str, list[np.ndarray]] = {c: [] for c in columns}
        for path, rgs in self._groups():
            t = read_parquet(path, columns=list(columns), row_groups=rgs)
            for c in columns:
                parts[c].append(column_array(t[c]))
        out = {c: np.concatenate(v) for c, v in parts.items()}
        if len(out[columns[0]]) != self.num_frames:
            raise CorruptDataError(
                f"{self.version.ref}: data files hold {len(out[columns[0]])} frames for "
                f"episodes [{self.start}, {self.stop}), metadata says {self.num_frames}"
            )
        return out

    def decode_images(self, out: np.ndarray | None = None) -> np.ndarray:
        """All images of the view as (N, H, W, 3) uint8 (decoded into ``out`` if given)."""
        s = self.version.image_size
        if out is None:
            out = np.empty((self.num_frames, s, s, 3), dtype=np.uint8)
        k = 0
        for path, rgs in self._groups():
            col = read_parquet(path, columns=[keys.OBS_IMAGE], row_groups=rgs)[keys.OBS_IMAGE].combine_chunks()
            for data in col.field("bytes").to_pylist():
                img = decode_png(data, path)
                if img.shape != (s, s, 3):
                    raise CorruptDataError(f"file {path}: an image is {img.shape}, info.json says {(s, s, 3)}")
                out[k] = img
                k += 1
        if k != self.num_frames:
            raise CorruptDataError(f"{self.version.ref}: found {k} images, metadata says {self.num_frames}")
        return out

    def episode(self, index: int) -> dict[str, np.ndarray]:
        """One episode's frame columns, images decoded (``index`` is the episode index)."""
        if not self.start <= index < self.stop:
            raise ConfigError(f"episode {index} is not in {self.ref} (episodes {self.start}..{self.stop - 1})")
        return self.version.view(index, index + 1).episodes_arrays()

    def episodes_arrays(self) -> dict[str, np.ndarray]:
        arrays = self.read_columns()
        arrays[keys.OBS_IMAGE] = self.decode_images()
        return arrays

    def iter_episodes(self) -> Iterator[dict[str, np.ndarray]]:
        """Each episode of the view as a dict of arrays (images decoded), in order."""
        for i in range(self.start, self.stop):
            yield self.episode(i)

    def split(self, holdout: int | float) -> tuple[DatasetView, DatasetView]:
        """(train, held-out): the held-out part is the last ``holdout`` episodes (or that fraction)."""
        n = self.num_episodes
        k = int(round(holdout * n)) if isinstance(holdout, float) and holdout < 1 else int(holdout)
        if not 1 <= k < n:
            raise ConfigError(
                f"holdout {holdout!r} of {self.ref} ({n} episodes) must leave at least one episode on each side"
            )
        cut = self.stop - k
        return DatasetView(self.version, self.start, cut), DatasetView(self.version, cut, self.stop)

    def describe(self) -> dict[str, Any]:
        return {
            "ref": self.ref,
            "version_hash": self.version.hash,
            "content_hash": self.content_hash,
            "episodes": self.num_episodes,
            "frames": self.num_frames,
            "success_rate": self.success_rate,
        }


def open_version(ref: str | versions.Ref) -> DatasetVersion:
    r, root = versions.resolve(ref)
    assert r.version is not None  # resolve() fills in the version
    return DatasetVersion(r.name, r.version, root)


def open_view(ref: str | versions.Ref | DatasetView) -> DatasetView:
    """The view a reference names: a whole version or its tier ``:K``."""
    if isinstance(ref, DatasetView):
        return ref
    r, root = versions.resolve(ref)
    assert r.version is not None  # resolve() fills in the version
    v = DatasetVersion(r.name, r.version, root)
    if r.tier is not None and r.tier > v.num_episodes:
        raise ConfigError(
            f"tier {r.tier} of {v.ref} is larger than the version ({v.num_episodes} episodes); "
            f"use :{v.num_episodes} or less, or collect more episodes"
        )
    return v.view(0, r.tier)
