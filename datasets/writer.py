"""Writing episodes as LeRobot v3.0 Parquet files with pyarrow (no LeRobot writer).

One data file holds a run of consecutive episodes, one Parquet row group per
episode, so a reader can fetch one episode alone.  Its episode metadata file
(``meta/episodes/...``, same file number) holds one row per episode: LeRobot's
columns, the per-episode stats and nsl's ``nsl/*`` columns.  Every file is
written to a temporary name and renamed into place; the episode metadata file is
written first, so the data file's presence marks the pair as complete.

Episodes are duck-typed records (``nsl.collectors.Episode`` fits)::

    images (T, H, W, 3) uint8, states (T, STATE_DIM), actions (T, ACTION_DIM), rewards (T,),
    terminated, truncated, success

Frame ``t`` is the observation before action ``t``; ``next.done`` is true only on
the last frame of a terminated episode, ``next.truncated`` only on the last
frame of a truncated one, ``next.success`` on the last frame of a success.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from nsl import keys
from nsl.errors import ConfigError
from nsl.workspace import atomic_write_bytes, atomic_write_json

from . import layout
from . import stats as statslib

PNG_COMPRESSION = 3  # zlib level: level 3 is within 10% of level 6's size at 2/3 of its time


class EpisodeLike(Protocol):
    images: np.ndarray
    states: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminated: bool
    truncated: bool
    success: bool


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG bytes of an (H, W, 3) uint8 RGB image."""
    import cv2

    ok, buf = cv2.imencode(
        ".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, PNG_COMPRESSION]
    )
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def episode_frames(
    ep: EpisodeLike, episode_index: int, first_index: int, task_index: int = 0, fps: int = keys.FPS
) -> dict[str, np.ndarray]:
    """The frame columns of one episode as arrays (images still raw uint8)."""
    images = np.asarray(ep.images)
    t = len(images)
    if t == 0 or images.dtype != np.uint8 or images.ndim != 4 or images.shape[-1] != 3:
        raise ConfigError(
            f"episode {episode_index}: images must be (T, H, W, 3) uint8 with T >= 1, got {images.shape}:{images.dtype}"
        )
    last = np.zeros(t, dtype=bool)
    last[-1] = True
    frames = {
        keys.OBS_IMAGE: images,
        keys.OBS_STATE: np.asarray(ep.states, dtype=np.float32).reshape(t, keys.STATE_DIM),
        keys.ACTION: np.asarray(ep.actions, dtype=np.float32).reshape(t, keys.ACTION_DIM),
        keys.REWARD: np.asarray(ep.rewards, dtype=np.float32).reshape(t),
        keys.DONE: last & bool(ep.terminated),
        keys.SUCCESS: last & bool(ep.success),
        keys.TRUNCATED: last & bool(ep.truncated and not ep.terminated),
        keys.TIMESTAMP: (np.arange(t) / fps).astype(np.float32),
        keys.FRAME_INDEX: np.arange(t, dtype=np.int64),
        keys.EPISODE_INDEX: np.full(t, episode_index, dtype=np.int64),
        keys.INDEX: np.arange(first_index, first_index + t, dtype=np.int64),
        keys.TASK_INDEX: np.full(t, task_index, dtype=np.int64),
    }
    return frames


def content_hash(frames: dict[str, np.ndarray]) -> str:
    """sha256 over an episode's raw arrays (independent of where it is stored)."""
    h = hashlib.sha256()
    for k in (keys.OBS_IMAGE, keys.OBS_STATE, keys.ACTION, keys.REWARD, keys.DONE, keys.SUCCESS, keys.TRUNCATED):
        a = np.ascontiguousarray(frames[k])
        h.update(f"{k}:{a.dtype.str}:{a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


_POOL: list[ThreadPoolExecutor] = []


def encode_pngs(images: Sequence[np.ndarray]) -> list[bytes]:
    """PNG bytes of many images, on every core (OpenCV releases the GIL while encoding)."""
    cores = os.cpu_count() or 1
    if cores < 2 or len(images) < 64:
        return [encode_png(im) for im in images]
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(cores, thread_name_prefix="nsl-png"))
    parts = np.array_split(np.arange(len(images)), 4 * cores)
    done = _POOL[0].map(lambda idx: [encode_png(images[i]) for i in idx], parts)
    return [png for part in done for png in part]


def frame_table(frames: dict[str, np.ndarray], schema: pa.Schema, pngs: Sequence[bytes] | None = None) -> pa.Table:
    """Arrow table of one episode's frames, images embedded as PNG bytes (``pngs``: already encoded)."""
    cols = []
    for name in schema.names:
        v = frames[name]
        if name in layout.IMAGE_KEYS:
            png = pa.array(pngs if pngs is not None else [encode_png(im) for im in v], type=pa.binary())
            cols.append(pa.StructArray.from_arrays([png, pa.nulls(len(v), pa.string())], names=["bytes", "path"]))
        elif v.ndim == 2:
            cols.append(pa.FixedSizeListArray.from_arrays(pa.array(v.reshape(-1)), v.shape[1]))
        else:
            cols.append(pa.array(v))
    return pa.Table.from_arrays(cols, schema=schema)


def _parquet_bytes(tables: Sequence[pa.Table], schema: pa.Schema, no_dictionary: Sequence[str] = ()) -> bytes:
    sink = io.BytesIO()
    use_dict = [n for n in schema.names if n not in no_dictionary]
    with pq.ParquetWriter(sink, schema, compression="snappy", use_dictionary=use_dict) as w:
        for t in tables:
            w.write_table(t, row_group_size=max(1, t.num_rows))
    return sink.getvalue()


def write_file_pair(
    root: Path,
    file_number: int,
    episodes: Sequence[EpisodeLike],
    first_episode: int,
    first_frame: int,
    image_size: int,
    chunks_size: int = layout.DEFAULT_CHUNKS_SIZE,
    task_index: int = 0,
    fps: int = keys.FPS,
) -> list[dict[str, Any]]:
    """Write data file ``file_number`` and its episode metadata under ``root``; return the episode rows."""
    schema = layout.frame_schema(image_size)
    loc = layout.file_location(file_number, chunks_size)
    tables, rows, all_frames = [], [], []
    frame = first_frame
    for j, ep in enumerate(episodes):
        frames = episode_frames(ep, first_episode + j, frame, task_index, fps)
        if frames[keys.OBS_IMAGE].shape[1:3] != (image_size, image_size):
            raise ConfigError(
                f"episode {first_episode + j}: images are {frames[keys.OBS_IMAGE].shape[1:3]}, "
                f"the dataset is {image_size}x{image_size}"
            )
        all_frames.append(frames)
        frame += len(frames[keys.INDEX])
    pngs = encode_pngs([im for f in all_frames for im in f[keys.OBS_IMAGE]])
    frame, at = first_frame, 0
    for j, (ep, frames) in enumerate(zip(episodes, all_frames)):
        idx = first_episode + j
        t = len(frames[keys.INDEX])
        tables.append(frame_table(frames, schema, pngs[at : at + t]))
        at += t
        row = {
            "episode_index": idx,
            "tasks": [layout.DEFAULT_TASK],
            "length": t,
            "data/chunk_index": loc["chunk_index"],
            "data/file_index": loc["file_index"],
            "dataset_from_index": frame,
            "dataset_to_index": frame + t,
            **statslib.to_columns(statslib.episode_stats(frames, layout.IMAGE_KEYS)),
            "meta/episodes/chunk_index": loc["chunk_index"],
            "meta/episodes/file_index": loc["file_index"],
            layout.EP_SUCCESS: bool(ep.success),
            layout.EP_TERMINATED: bool(ep.terminated),
            layout.EP_TRUNCATED: bool(ep.truncated and not ep.terminated),
            layout.EP_CONTENT_HASH: content_hash(frames),
        }
        rows.append(row)
        frame += t
    write_episode_rows(root, file_number, rows, chunks_size)
    atomic_write_bytes(
        Path(root) / layout.data_path(file_number, chunks_size),
        _parquet_bytes(tables, schema, no_dictionary=layout.IMAGE_KEYS),
    )
    return rows


def write_episode_rows(
    root: Path, file_number: int, rows: list[dict[str, Any]], chunks_size: int = layout.DEFAULT_CHUNKS_SIZE
) -> None:
    table = pa.Table.from_pylist(rows)
    path = Path(root) / layout.episodes_path(file_number, chunks_size)
    atomic_write_bytes(path, _parquet_bytes([table], table.schema))


def write_tasks(root: Path, tasks: Sequence[str] = (layout.DEFAULT_TASK,)) -> None:
    """``meta/tasks.parquet`` as LeRobot writes it (a pandas frame indexed by task string)."""
    import pandas as pd

    sink = io.BytesIO()
    pd.DataFrame({"task_index": np.arange(len(tasks), dtype=np.int64)}, index=list(tasks)).to_parquet(sink)
    atomic_write_bytes(Path(root) / layout.TASKS_PATH, sink.getvalue())


def write_meta(root: Path, info: layout.DatasetInfo, stats: statslib.Stats, nsl_meta: dict[str, Any]) -> None:
    """The small metadata files of a version: info, stats, tasks and nsl provenance."""
    root = Path(root)
    atomic_write_bytes(root / layout.INFO_PATH, (json.dumps(info.to_dict(), indent=4) + "\n").encode())
    atomic_write_bytes(root / layout.STATS_PATH, (json.dumps(statslib.to_json(stats), indent=4) + "\n").encode())
    write_tasks(root)
    atomic_write_json(root / layout.NSL_META_PATH, nsl_meta)
