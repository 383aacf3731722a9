"""The store that carries NSL_HOME's folders between cluster nodes without a shared file system (``--store``),
against a real S3 server (moto) on 127.0.0.1: what a pull writes is what was pushed, byte for byte; a node's cache
skips what it holds; a damaged object is refused."""

from __future__ import annotations

import pytest

from nsl.errors import ConfigError, CorruptDataError, UnknownReferenceError


def _folder(root, files: dict[str, bytes]):
    for rel, data in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)


FILES = {"data/chunk-000/file-000.parquet": b"x" * 5000, "meta/info.json": b"{}", "manifest.json": b'{"hash": 1}'}


def test_a_pushed_folder_pulls_into_another_home_byte_for_byte_and_a_second_time_moves_nothing(s3, s3_server, tmp_path):
    from nsl.share.store import Store

    driver, node = tmp_path / "driver", tmp_path / "node"
    _folder(driver / "datasets/d/v1", FILES)
    store = Store(f"{s3}/runs")
    assert store.push(driver, "datasets/d/v1") == len(FILES)
    puts = len(s3_server.puts())
    assert store.push(driver, "datasets/d/v1") == 0 and len(s3_server.puts()) == puts  # nothing sent again
    assert store.pull(node, "datasets/d/v1") == len(FILES)
    assert {rel: (node / "datasets/d/v1" / rel).read_bytes() for rel in FILES} == FILES
    assert store.pull(node, "datasets/d/v1") == 0  # the node's cache holds it
    (node / "datasets/d/v1/meta/info.json").unlink()  # a file gone from the cache is fetched again, alone
    assert store.pull(node, "datasets/d/v1") == 1 and (node / "datasets/d/v1/meta/info.json").read_bytes() == b"{}"


def test_a_damaged_object_or_a_missing_folder_is_refused_in_one_line(s3, tmp_path):
    import fsspec

    from nsl.share.store import Store

    driver, node = tmp_path / "driver", tmp_path / "node"
    _folder(driver / "runs/r", {"final/model.safetensors": b"w" * 100})
    store = Store(f"{s3}/runs")
    store.push(driver, "runs/r")
    fs, _ = fsspec.core.url_to_fs(s3)
    fs.pipe_file(f"{s3}/runs/home/runs/r/final/model.safetensors", b"v" * 100)  # same size, other bytes
    with pytest.raises(CorruptDataError, match=r"runs/r/final/model.safetensors has sha256 .* the store is damaged"):
        store.pull(node, "runs/r")
    assert not (node / "runs/r/final/model.safetensors").exists()  # nothing unverified is left in place
    assert not list((node / "runs/r/final").glob("*.tmp"))
    with pytest.raises(UnknownReferenceError, match=r"holds no runs/other; the driver pushes"):
        store.pull(node, "runs/other")


def test_store_options_are_checked():
    from nsl.cluster import open_executor
    from nsl.share.store import parse_store

    with pytest.raises(ConfigError, match=r"--store 'bucket/x' is not a URL"):
        parse_store("bucket/x")
    assert parse_store(None) is None and parse_store("s3://b/p/") == "s3://b/p"
    with pytest.raises(ConfigError, match=r"give --cluster too"):
        open_executor("local", store="s3://b/p")
