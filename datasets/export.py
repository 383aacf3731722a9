"""Export a version (or a tier of it) as a plain LeRobot v3.0 directory, ready for a hub upload.

Where the native directory differs from a plain LeRobot dataset, the export
fixes it: the nsl-only files (``manifest.json``, ``meta/nsl.json``) are left out
and their provenance goes into a ``README.md`` dataset card; hard links become
copies; a tier ``NAME@vN:K`` is cut to its first K episodes (the data file
holding episode K-1 is rewritten with the row groups before it, metadata and
stats are recomputed for the tier).
"""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from nsl.errors import ConfigError
from nsl.workspace import atomic_write_bytes

from . import layout, writer
from . import stats as statslib
from .reader import DatasetView, read_episode_stats, read_parquet

CARD = """# {ref}

Simulated vision-based bin grasping episodes collected with nsl ("never stop learning"),
in LeRobotDataset v3.0 format ({episodes} episodes, {frames} frames, success rate {success:.1%}).

- content hash of these episodes: `{content_hash}`
- source version hash: `{version_hash}`

Frame `t` is the camera image and gripper state before action `t`; `next.reward` is the
reward of that step, `next.done` marks the last frame of a terminated episode and
`next.truncated` the last frame of a time-limit truncation.

## Provenance

```json
{provenance}
```
"""


def export(view: DatasetView, out: Path, repo_id: str | None = None) -> Path:
    """Write ``view`` as a LeRobot dataset directory at ``out`` (which must not exist)."""
    out = Path(out)
    if out.exists() and any(out.iterdir()):
        raise ConfigError(f"export target {out} exists and is not empty; choose a new --out directory")
    if view.start != 0:
        raise ConfigError(f"only whole versions and tiers (first K episodes) can be exported, not {view.ref}")
    v = view.version
    view.check()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        ep = v.episodes
        last_file = int(ep.file_number[view.stop - 1])
        cut = view.stop < v.num_episodes and int(ep.file_number[view.stop]) == last_file  # last file partly in
        for n in range(last_file + 1):
            d, e = v.data_file(n), layout.episodes_path(n, v.info.chunks_size)
            (tmp / d).parent.mkdir(parents=True, exist_ok=True)
            (tmp / e).parent.mkdir(parents=True, exist_ok=True)
            if n == last_file and cut:
                rgs = ep.row_group[: view.stop][ep.file_number[: view.stop] == n].tolist()
                _write_subset(v.root / d, tmp / d, rgs)
                rows = read_parquet(v.root / e).slice(0, len(rgs))
                atomic_write_bytes(tmp / e, _table_bytes(rows))
            else:
                shutil.copyfile(v.root / d, tmp / d)
                shutil.copyfile(v.root / e, tmp / e)
        episode_files = [layout.episodes_path(n, v.info.chunks_size) for n in range(last_file + 1)]
        per_episode = read_episode_stats(tmp, episode_files)
        info = layout.DatasetInfo.new(v.image_size, view.num_episodes, view.num_frames)
        atomic_write_bytes(tmp / layout.INFO_PATH, (json.dumps(info.to_dict(), indent=4) + "\n").encode())
        atomic_write_bytes(
            tmp / layout.STATS_PATH,
            (json.dumps(statslib.to_json(statslib.aggregate(per_episode)), indent=4) + "\n").encode(),
        )
        writer.write_tasks(tmp)
        card = _card_metadata() + CARD.format(
            ref=repo_id or view.ref,
            episodes=view.num_episodes,
            frames=view.num_frames,
            success=view.success_rate,
            content_hash=view.content_hash,
            version_hash=v.hash,
            provenance=json.dumps(
                {"source": view.ref, **v.provenance, "created": v.manifest.get("created", {})}, indent=2
            ),
        )
        atomic_write_bytes(tmp / "README.md", card.encode())
        if out.exists():
            out.rmdir()
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _card_metadata() -> str:
    """The card's YAML front matter (what the Hub indexes the dataset by)."""
    from huggingface_hub import DatasetCardData

    data = DatasetCardData(
        license="apache-2.0",
        task_categories=["robotics"],
        tags=["LeRobot", "nsl", "grasping"],
        configs=[{"config_name": "default", "data_files": "data/*/*.parquet"}],
    )
    return f"---\n{data.to_yaml()}\n---\n\n"


def _table_bytes(table: pa.Table) -> bytes:
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="snappy")
    return sink.getvalue().to_pybytes()


def _write_subset(src: Path, dst: Path, row_groups: list[int]) -> None:
    """Copy some row groups (episodes) of a data file, keeping one row group per episode."""
    f = pq.ParquetFile(src)
    sink = pa.BufferOutputStream()
    with pq.ParquetWriter(sink, f.schema_arrow, compression="snappy") as w:
        for g in row_groups:
            w.write_table(f.read_row_group(g))
    atomic_write_bytes(dst, sink.getvalue().to_pybytes())
