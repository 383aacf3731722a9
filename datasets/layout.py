"""The on-disk layout of an nsl episode dataset: LeRobotDataset v3.0 plus two nsl files.

A dataset version is a directory that LeRobot's ``LeRobotDataset(repo_id, root=dir)``
opens as is::

    vN/
      meta/info.json                                   LeRobot: features, totals, path templates
      meta/stats.json                                  LeRobot: min/max/mean/std/count per feature
      meta/tasks.parquet                               LeRobot: the task strings
      meta/episodes/chunk-000/file-000.parquet         LeRobot: one row per episode (+ nsl/* columns)
      data/chunk-000/file-000.parquet                  LeRobot: one row per frame, one row group per episode
      meta/nsl.json                                    nsl: provenance that defines the content (hashed)
      manifest.json                                    nsl: file hashes, version hash, creation record

Data file number ``n`` (counting from 0 over the whole dataset) is stored as
``chunk_index = n // chunks_size``, ``file_index = n % chunks_size``; the episode
metadata file with the same number describes exactly the episodes of that data
file, so appending a version adds files and never rewrites one.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import pyarrow as pa

from nsl import keys
from nsl.errors import CorruptDataError, IncompatibleVersionError

CODEBASE_VERSION = "v3.0"  # the LeRobotDataset format version we write
NSL_FORMAT = 1  # version of the nsl additions (meta/nsl.json, manifest.json, nsl/* columns)

INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
TASKS_PATH = "meta/tasks.parquet"
NSL_META_PATH = "meta/nsl.json"
MANIFEST_PATH = "manifest.json"
CHUNK_FILE_PATTERN = "chunk-{chunk_index:03d}/file-{file_index:03d}"
DATA_PATH = "data/" + CHUNK_FILE_PATTERN + ".parquet"
EPISODES_PATH = "meta/episodes/" + CHUNK_FILE_PATTERN + ".parquet"

VERSION_DIR = "v{version}"  # under $NSL_HOME/datasets/NAME/
STAGING_DIR = ".staging"  # an unfinished collection of NAME (resumable)
CACHE_DIR = "datasets/{version_hash}"  # under $NSL_HOME/cache/: decoded uint8 images

DEFAULT_CHUNKS_SIZE = 1000  # files per chunk directory (LeRobot's default)
DEFAULT_EPISODES_PER_FILE = 100  # episodes per data file (about 1.5 MB at 64x64)
DEFAULT_TASK = "grasp any object from the bin"
ROBOT_TYPE = "nsl_mocap_gripper"

# Columns of meta/episodes/*.parquet that LeRobot does not define.
EP_SUCCESS = "nsl/success"
EP_TERMINATED = "nsl/terminated"
EP_TRUNCATED = "nsl/truncated"
EP_CONTENT_HASH = "nsl/content_hash"  # sha256 over the episode's raw arrays (tier hashes build on it)

IMAGE_KEYS = (keys.OBS_IMAGE,)
BOOL_KEYS = (keys.DONE, keys.SUCCESS, keys.TRUNCATED)
INDEX_KEYS = (keys.FRAME_INDEX, keys.EPISODE_INDEX, keys.INDEX, keys.TASK_INDEX)


def file_location(file_number: int, chunks_size: int = DEFAULT_CHUNKS_SIZE) -> dict[str, int]:
    """``{"chunk_index", "file_index"}`` of the ``file_number``-th file of a dataset."""
    return {"chunk_index": file_number // chunks_size, "file_index": file_number % chunks_size}


def data_path(file_number: int, chunks_size: int = DEFAULT_CHUNKS_SIZE) -> str:
    return DATA_PATH.format(**file_location(file_number, chunks_size))


def episodes_path(file_number: int, chunks_size: int = DEFAULT_CHUNKS_SIZE) -> str:
    return EPISODES_PATH.format(**file_location(file_number, chunks_size))


def features(image_size: int) -> dict[str, dict[str, Any]]:
    """The LeRobot feature dict of an nsl grasping dataset (frame columns in order)."""
    scalar = {"shape": [1], "names": None}
    return {
        keys.OBS_IMAGE: {
            "dtype": "image",
            "shape": [image_size, image_size, 3],
            "names": ["height", "width", "channels"],
        },
        keys.OBS_STATE: {"dtype": "float32", "shape": [keys.STATE_DIM], "names": list(keys.STATE_NAMES)},
        keys.ACTION: {"dtype": "float32", "shape": [keys.ACTION_DIM], "names": list(keys.ACTION_NAMES)},
        keys.REWARD: {"dtype": "float32", **scalar},
        keys.DONE: {"dtype": "bool", **scalar},
        keys.SUCCESS: {"dtype": "bool", **scalar},
        keys.TRUNCATED: {"dtype": "bool", **scalar},
        keys.TIMESTAMP: {"dtype": "float32", **scalar},
        keys.FRAME_INDEX: {"dtype": "int64", **scalar},
        keys.EPISODE_INDEX: {"dtype": "int64", **scalar},
        keys.INDEX: {"dtype": "int64", **scalar},
        keys.TASK_INDEX: {"dtype": "int64", **scalar},
    }


def _arrow_type(ft: dict[str, Any]) -> pa.DataType:
    if ft["dtype"] == "image":
        return pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    base = pa.from_numpy_dtype(ft["dtype"]) if ft["dtype"] != "bool" else pa.bool_()
    return base if list(ft["shape"]) == [1] else pa.list_(base, int(ft["shape"][0]))


def _hf_feature(ft: dict[str, Any]) -> dict[str, Any]:
    """The Hugging Face ``datasets`` feature JSON for one LeRobot feature."""
    if ft["dtype"] == "image":
        return {"_type": "Image"}
    value = {"dtype": ft["dtype"], "_type": "Value"}
    if list(ft["shape"]) == [1]:
        return value
    return {"feature": value, "length": int(ft["shape"][0]), "_type": "List"}


def frame_schema(image_size: int) -> pa.Schema:
    """Arrow schema of a data file, with the ``huggingface`` metadata that ``datasets.Image`` needs."""
    fts = features(image_size)
    hf = {"info": {"features": {k: _hf_feature(ft) for k, ft in fts.items()}}}
    return pa.schema([(k, _arrow_type(ft)) for k, ft in fts.items()], metadata={"huggingface": json.dumps(hf)})


def _check(cond: bool, path: str, what: str) -> None:
    if not cond:
        raise CorruptDataError(
            f"{path}: {what}; the file is not a valid nsl dataset info.json (run `nsl dataset verify` on the version)"
        )


@dataclass(frozen=True)
class DatasetInfo:
    """Typed mirror of ``meta/info.json`` (LeRobot v3.0); validates itself."""

    total_episodes: int
    total_frames: int
    features: dict[str, dict[str, Any]]
    fps: int = keys.FPS
    total_tasks: int = 1
    codebase_version: str = CODEBASE_VERSION
    robot_type: str | None = ROBOT_TYPE
    chunks_size: int = DEFAULT_CHUNKS_SIZE  # max files per chunk directory
    data_files_size_in_mb: int = 100  # LeRobot's writer limit; informative for us (we split by episodes)
    video_files_size_in_mb: int = 200  # unused: images are embedded, there are no videos
    splits: dict[str, str] = field(default_factory=dict)  # LeRobot: {"train": "0:N"}
    data_path: str = DATA_PATH
    video_path: str | None = None
    source: str = INFO_PATH  # where it was read from (for messages); not written

    def __post_init__(self) -> None:
        p = self.source
        if self.codebase_version != CODEBASE_VERSION:
            raise IncompatibleVersionError(
                f"{p}: codebase_version {self.codebase_version!r} is not {CODEBASE_VERSION!r}; convert the "
                "dataset with lerobot's v3.0 converter or re-collect it"
            )
        _check(
            self.total_episodes >= 0 and self.total_frames >= self.total_episodes,
            p,
            f"totals episodes={self.total_episodes} frames={self.total_frames} are inconsistent",
        )
        _check(self.fps > 0 and self.chunks_size > 0, p, f"fps={self.fps} chunks_size={self.chunks_size}")
        _check(self.data_path == DATA_PATH, p, f"data_path {self.data_path!r} is not {DATA_PATH!r}")
        _check(self.video_path is None, p, "videos are not used by nsl datasets (video_path must be null)")
        expected = features(self.image_size)
        state = self.features.get(keys.OBS_STATE) or {}
        if state.get("names") is not None and state.get("names") != keys.STATE_NAMES:
            raise IncompatibleVersionError(
                f"{p}: the dataset's gripper state is {state.get('names')}, but this nsl records "
                f"{keys.STATE_NAMES} (environment v2); collect the dataset again with this nsl, "
                "or set NSL_HOME to a new workspace"
            )
        for k, ft in expected.items():
            got = self.features.get(k)
            _check(
                got is not None and got["dtype"] == ft["dtype"] and list(got["shape"]) == ft["shape"],
                p,
                f"feature {k!r} is {got!r}, expected dtype {ft['dtype']} shape {ft['shape']}",
            )

    @property
    def image_size(self) -> int:
        shape = self.features.get(keys.OBS_IMAGE, {}).get("shape") or [0]
        return int(shape[0])

    @classmethod
    def new(cls, image_size: int, total_episodes: int, total_frames: int, **kw: Any) -> DatasetInfo:
        return cls(
            total_episodes=total_episodes,
            total_frames=total_frames,
            features=features(image_size),
            splits={"train": f"0:{total_episodes}"},
            **kw,
        )

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("source")
        order = [
            "codebase_version",
            "robot_type",
            "total_episodes",
            "total_frames",
            "total_tasks",
            "chunks_size",
            "data_files_size_in_mb",
            "video_files_size_in_mb",
            "fps",
            "splits",
            "data_path",
            "video_path",
            "features",
        ]
        return {k: d[k] for k in order}

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = INFO_PATH) -> DatasetInfo:
        known = set(cls.__dataclass_fields__) - {"source"}
        missing = {"total_episodes", "total_frames", "features"} - set(d)
        _check(not missing, source, f"missing fields {sorted(missing)}")
        return cls(**{k: v for k, v in d.items() if k in known}, source=source)

    @classmethod
    def load(cls, root: Path) -> DatasetInfo:
        path = Path(root) / INFO_PATH
        try:
            d = json.loads(path.read_text())
        except FileNotFoundError:
            raise CorruptDataError(f"{path} is missing; this is not a dataset version directory") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as e:
            raise CorruptDataError(f"{path} is not valid JSON ({e}); run `nsl dataset verify`") from None
        return cls.from_dict(d, source=str(path))
