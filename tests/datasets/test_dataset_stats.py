"""meta/stats.json (pooled from per-episode stats) equals numpy over the raw arrays."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nsl import keys


def test_stats_match_numpy_over_all_frames_across_files_and_versions(make_synth):
    make_synth("measured", [3, 4, 2, 5, 3], truncated={2}, successes={0, 4})
    v = make_synth("measured", [6, 2, 4], start=5, successes={6})  # v2 pools v1's episodes and new ones
    stats = json.loads((v.root / "meta/stats.json").read_text())
    raw = v.view().episodes_arrays()
    n = v.num_frames
    assert n == 29

    pixels = raw[keys.OBS_IMAGE].reshape(-1, 3).astype(np.float64) / 255.0
    s = stats[keys.OBS_IMAGE]
    assert np.asarray(s["mean"]).shape == (3, 1, 1) and s["count"] == [n]
    np.testing.assert_allclose(np.ravel(s["mean"]), pixels.mean(0), rtol=1e-12)
    np.testing.assert_allclose(np.ravel(s["std"]), pixels.std(0), rtol=1e-9)
    np.testing.assert_array_equal(np.ravel(s["min"]), pixels.min(0))
    np.testing.assert_array_equal(np.ravel(s["max"]), pixels.max(0))

    for key in (keys.OBS_STATE, keys.ACTION, keys.REWARD, keys.DONE, keys.SUCCESS, keys.INDEX, keys.FRAME_INDEX):
        x = raw[key].reshape(n, -1)
        f = x.astype(np.float64)
        s = stats[key]
        assert s["count"] == [n], key
        np.testing.assert_allclose(s["mean"], f.mean(0), rtol=1e-9, atol=1e-12, err_msg=key)
        np.testing.assert_allclose(s["std"], f.std(0), rtol=1e-9, atol=1e-12, err_msg=key)
        np.testing.assert_array_equal(s["min"], x.min(0), err_msg=key)
        np.testing.assert_array_equal(s["max"], x.max(0), err_msg=key)
    assert stats[keys.DONE]["mean"] == [pytest.approx(7 / n)]  # 7 terminated episodes (one truncated)
    assert stats[keys.DONE]["max"] == [True] and stats[keys.DONE]["min"] == [False]
