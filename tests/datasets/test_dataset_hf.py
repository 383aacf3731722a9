"""`to_hf_dataset`: a version's frames as an Arrow-backed Hugging Face `datasets.Dataset`, nothing copied."""

from __future__ import annotations

import numpy as np

from nsl import keys
from nsl.datasets import api


def test_same_frames_as_nsls_reader_without_a_cache_copy(make_synth, tmp_path, monkeypatch):
    import datasets as hf_datasets

    monkeypatch.setattr(hf_datasets.config, "HF_DATASETS_CACHE", tmp_path / "cache")
    make_synth("hfview", [3, 5, 2, 4], successes={1, 3})
    ds = api.to_hf_dataset("hfview")
    want = api.open_view("hfview").episodes_arrays()
    assert len(ds) == len(want[keys.INDEX]) == 14
    assert ds.cache_files == [] and not (tmp_path / "cache").exists()  # built from memory-mapped Parquet
    np_ds = ds.with_format("numpy")
    for k in (keys.OBS_STATE, keys.ACTION, keys.REWARD, keys.EPISODE_INDEX, keys.FRAME_INDEX, keys.SUCCESS):
        got = np.asarray(np_ds[k]).reshape(want[k].shape)
        assert np.array_equal(got, want[k]), k
    images = np.stack([np.asarray(ds[i][keys.OBS_IMAGE]) for i in range(len(ds))])
    assert np.array_equal(images, want[keys.OBS_IMAGE])  # decoded PNGs: bit-identical pixels
    # map and filter work on it; a tier is a view of its first episodes
    successes = ds.filter(lambda row: bool(row[keys.SUCCESS]))
    assert len(successes) == int(want[keys.SUCCESS].sum())
    tier = api.to_hf_dataset("hfview:2")
    assert tier[keys.INDEX] == list(range(8))
