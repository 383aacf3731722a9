"""The on-disk format is LeRobot v3.0: LeRobot's own reader returns our data bit for bit."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
import torch

from nsl import keys
from nsl.datasets import api
from nsl.errors import CorruptDataError, IncompatibleVersionError
from tests.conftest import run_cli


def _uint8_hwc(t: torch.Tensor) -> np.ndarray:
    return (t * 255).round().to(torch.uint8).permute(1, 2, 0).numpy()


def _assert_lerobot_matches(ds, ours: dict[str, np.ndarray]) -> None:
    assert len(ds) == len(ours[keys.INDEX])
    for i in range(len(ds)):
        item = ds[i]
        assert np.array_equal(_uint8_hwc(item[keys.OBS_IMAGE]), ours[keys.OBS_IMAGE][i]), f"image of frame {i}"
        assert np.array_equal(item[keys.ACTION].numpy(), ours[keys.ACTION][i])
        assert np.array_equal(item[keys.OBS_STATE].numpy(), ours[keys.OBS_STATE][i])
        assert item[keys.REWARD].item() == ours[keys.REWARD][i]
        assert item[keys.DONE].item() == ours[keys.DONE][i]
        assert item[keys.EPISODE_INDEX].item() == ours[keys.EPISODE_INDEX][i]


def test_lerobot_opens_a_collected_dataset_with_identical_content(lerobot_offline, tmp_path):
    assert (
        run_cli(
            "collect",
            "--shift",
            "harsh_lighting",
            "--episodes",
            "6",
            "--policy",
            "oracle:0.5",
            "--data",
            "grasp-harsh",
            "--episodes-per-file",
            "4",
        )
        == 0
    )
    view = api.open_view("grasp-harsh")
    ours = view.episodes_arrays()
    assert ours[keys.OBS_IMAGE].shape == (view.num_frames, 64, 64, 3)
    assert 0 < ours[keys.REWARD].sum() < view.num_episodes + 1  # some grasps succeed, some fail

    ds = lerobot_offline("local/grasp-harsh", root=view.version.root)
    assert ds.meta.total_episodes == 6 and ds.meta.image_keys == [keys.OBS_IMAGE]
    _assert_lerobot_matches(ds, ours)

    # A tier through LeRobot's own episode filter, and the exported tier as a standalone dataset.
    tier = api.open_view("grasp-harsh:5").episodes_arrays()
    _assert_lerobot_matches(lerobot_offline("local/grasp-harsh", root=view.version.root, episodes=list(range(5))), tier)
    out = api.export("grasp-harsh:5", tmp_path / "export")
    assert not (out / "manifest.json").exists() and not (out / "meta/nsl.json").exists()
    assert "oracle" in (out / "README.md").read_text()
    exported = lerobot_offline("user/grasp-harsh", root=out)
    assert exported.meta.total_episodes == 5
    _assert_lerobot_matches(exported, tier)
    stats = json.loads((out / "meta/stats.json").read_text())
    assert stats[keys.ACTION]["count"] == [len(tier[keys.INDEX])]


def test_frame_flags_and_row_groups(make_synth):
    v = make_synth("flags", [3, 4, 2, 5], truncated={1}, successes={0, 3}, episodes_per_file=3)
    f0 = pq.ParquetFile(v.root / "data/chunk-000/file-000.parquet")
    assert f0.metadata.num_row_groups == 3  # one row group per episode
    assert [f0.metadata.row_group(g).num_rows for g in range(3)] == [3, 4, 2]
    assert f0.schema_arrow.field(keys.OBS_IMAGE).type.names == ["bytes", "path"]
    assert json.loads(f0.schema_arrow.metadata[b"huggingface"])["info"]["features"][keys.OBS_IMAGE] == {
        "_type": "Image"
    }

    a = v.view().read_columns()
    ends = np.cumsum([3, 4, 2, 5]) - 1
    assert np.flatnonzero(a[keys.DONE]).tolist() == [ends[0], ends[2], ends[3]]  # not on the truncation
    assert np.flatnonzero(a[keys.TRUNCATED]).tolist() == [ends[1]]
    assert np.flatnonzero(a[keys.SUCCESS]).tolist() == [ends[0], ends[3]]
    assert a[keys.INDEX].tolist() == list(range(14))
    assert a[keys.FRAME_INDEX][:5].tolist() == [0, 1, 2, 0, 1]
    np.testing.assert_allclose(a[keys.TIMESTAMP][:3], np.arange(3) / keys.FPS)
    # One episode alone comes from its own row group.
    ep = v.view().episode(2)
    assert ep[keys.OBS_IMAGE][:, 0, 0, 0].tolist() == [2, 2] and ep[keys.OBS_IMAGE][:, 0, 0, 1].tolist() == [0, 1]


def test_info_json_mirror_validates_itself(make_synth):
    v = make_synth("info", [2, 2])
    info = api.layout.DatasetInfo.load(v.root)
    assert info.total_episodes == 2 and info.image_size == 16 and info.to_dict()["splits"] == {"train": "0:2"}
    bad = {**info.to_dict(), "codebase_version": "v2.1"}
    with pytest.raises(IncompatibleVersionError, match="codebase_version 'v2.1'"):
        api.layout.DatasetInfo.from_dict(bad)
    bad = {**info.to_dict(), "features": {**info.features, keys.ACTION: {"dtype": "float32", "shape": [7]}}}
    with pytest.raises(CorruptDataError, match="feature 'action'"):
        api.layout.DatasetInfo.from_dict(bad)
    v1_state = {"dtype": "float32", "shape": [2], "names": ["gripper_opening", "wrist_height"]}
    bad = {**info.to_dict(), "features": {**info.features, keys.OBS_STATE: v1_state}}
    with pytest.raises(IncompatibleVersionError, match="collect the dataset again"):  # environment v1 data
        api.layout.DatasetInfo.from_dict(bad)


def test_a_pybullet_dataset_opens_in_lerobot_and_fine_tunes_the_base_with_no_new_flags(lerobot_offline):
    from nsl.catalog import Catalog

    collect = ["collect", "--engine", "pybullet", "--shift", "harsh_lighting@2", "--episodes", "4"]
    assert run_cli(*collect, "--policy", "oracle:0.5", "--data", "grasp-pb-harsh") == 0
    view = api.open_view("grasp-pb-harsh")
    env = view.version.provenance["collections"][-1]["spec"]["env"]
    assert env["engine"] == "pybullet" and env["shift_spec"]["name"] == "engine:pybullet+harsh_lighting@2"
    _assert_lerobot_matches(lerobot_offline("local/grasp-pb-harsh", root=view.version.root), view.episodes_arrays())

    # The fine-tune reads the engine from the data: its early-stopping evaluations run on PyBullet.
    train = ["train", "--init", "ckpt:base", "--data", "grasp-pb-harsh", "--steps", "2", "--name", "pb-ft"]
    assert run_cli(*train, "--eval-every", "2", "--eval-episodes", "2", "--workers", "1") == 0
    with Catalog() as cat:
        child = cat.resolve_checkpoint("ckpt:pb-ft@latest")
        assert child.shift == "engine:pybullet+harsh_lighting@2"
        assert {e.shift for e in cat.evaluations(child.id)} == {"engine:pybullet+harsh_lighting@2"}
