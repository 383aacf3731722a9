"""Damaged files are reported by `verify` and refused by the loader, naming the file; caches heal."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from nsl import keys
from nsl.datasets import api
from nsl.errors import CorruptDataError
from tests.conftest import run_cli

DATA = "data/chunk-000/file-001.parquet"


def _flip_byte(path, offset):
    raw = bytearray(path.read_bytes())
    raw[offset] ^= 0xFF
    path.write_bytes(bytes(raw))


@pytest.mark.parametrize("damage", ["truncated", "altered"])
def test_damaged_parquet_is_reported_and_refused(make_synth, capsys, damage):
    v = make_synth("fragile", [3, 4, 2, 5, 3, 4])
    api.make_sampler("fragile")  # builds the image cache while the files are intact
    p = v.root / DATA
    if damage == "truncated":
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    else:
        _flip_byte(p, p.stat().st_size // 3)

    assert run_cli("dataset", "verify", "fragile") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(p) in err and damage in err
    with pytest.raises(CorruptDataError, match=f"{p}.*{damage}"):
        api.make_sampler([("fragile", 1.0)])
    if damage == "truncated":  # even without re-hashing, reading it fails with the file's name
        with pytest.raises(CorruptDataError, match=f"{p} is damaged"):
            api.make_sampler("fragile", verify=False)
    # The first tier lies in the intact file and still loads.
    assert len(api.make_sampler("fragile:3")) > 0


def test_verify_all_and_files_added_after_publication(make_synth, capsys):
    v = make_synth("clean", [2, 3])
    assert run_cli("dataset", "verify") == 0
    assert "clean@v1 ok" in capsys.readouterr().out
    stray = v.root / "data/chunk-000/file-009.parquet"
    stray.write_bytes(b"junk")
    assert run_cli("dataset", "verify", "clean@v1") == 2
    assert str(stray) in capsys.readouterr().err


def test_image_cache_is_built_once_and_rebuilt_when_stale(make_synth):
    v = make_synth("cached", [3, 4, 2])
    s = api.make_sampler("cached")
    cache = api.image_cache(v)
    assert isinstance(cache, np.memmap) and cache.shape == (9, 16, 16, 3)
    assert np.array_equal(np.asarray(cache), v.view().decode_images())
    npy = Path(cache.filename)
    before = s.sample(64, np.random.default_rng(5))

    npy.write_bytes(npy.read_bytes()[:-100])  # truncated cache file
    again = api.make_sampler("cached").sample(64, np.random.default_rng(5))
    assert all(np.array_equal(before[k], again[k]) for k in before)
    meta = npy.parent / "cache.json"
    meta.write_text(json.dumps({**json.loads(meta.read_text()), "hash": "sha256:other"}))  # stale
    mtime = npy.stat().st_mtime_ns
    api.make_sampler("cached")
    assert npy.stat().st_mtime_ns != mtime and json.loads(meta.read_text())["hash"] == v.hash
    assert api.make_sampler("cached").sample(4, np.random.default_rng(0))[keys.OBS_IMAGE].dtype == np.uint8
