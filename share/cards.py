"""Dataset cards: the ``README.md`` a pushed dataset version carries.

The front matter makes the repository a LeRobot dataset for the Hub (tag
``LeRobot``) and points Hugging Face ``datasets`` at the Parquet frames
(``configs: data_files: data/*/*.parquet``), so ``load_dataset(REPO)`` works.
The body says what the data is: shift, policy, episodes, success rate,
environment version and the content hash a pull verifies.  Model cards are
rendered by the catalog (``nsl.catalog.render_model_card``) and passed in.
"""

from __future__ import annotations

import json
from typing import Any

DATA_FILES = "data/*/*.parquet"


def dataset_card(
    *,
    name: str,
    version: int,
    content_hash: str,
    episodes: int,
    frames: int,
    success_rate: float,
    shift: str,
    policy: str,
    env_version: str,
    codebase_version: str,
    provenance: dict[str, Any],
    license_id: str = "apache-2.0",
) -> str:
    """The card text of dataset ``name`` version ``version``."""
    from huggingface_hub import DatasetCardData

    data = DatasetCardData(
        license=license_id,
        task_categories=["robotics"],
        tags=["LeRobot", "nsl", "grasping", shift],
        configs=[{"config_name": "default", "data_files": DATA_FILES}],
        nsl={
            "name": name,
            "version": version,
            "content_hash": content_hash,
            "shift": shift,
            "policy": policy,
            "env_version": env_version,
            "episodes": episodes,
            "success_rate": round(success_rate, 4),
        },
    )
    body = f"""# {name} v{version}

Simulated vision-based bin grasping episodes made with nsl ("never stop learning"), a LeRobotDataset
({codebase_version}) with camera frames stored as PNG bytes in Parquet.

| | |
|---|---|
| shift | `{shift}` |
| policy | `{policy}` |
| episodes | {episodes} ({frames} frames) |
| success rate | {success_rate:.1%} |
| environment version | `{env_version}` |
| content hash | `{content_hash}` |

The content hash is sha256 over the sorted `(path, size, sha256)` of every file; `manifest.json` lists
them, and `nsl pull` checks each file against it before registering the version.

## Use

```bash
nsl pull URL@v{version}                       # into an nsl workspace, verified and catalogued
```

```python
from lerobot.datasets.lerobot_dataset import LeRobotDataset   # the Hub's LeRobot loader (tag {codebase_version})
import datasets; datasets.load_dataset("parquet", data_files="{DATA_FILES}")   # plain Arrow frames
```

Frame `t` is the camera image and gripper state before action `t`; `next.reward` is the reward of that
step, `next.done` marks the last frame of a terminated episode and `next.truncated` the last frame of a
time-limit truncation.

## Provenance

```json
{json.dumps(provenance, indent=2, sort_keys=True)}
```
"""
    return f"---\n{data.to_yaml()}\n---\n\n{body}"
