"""`nsl push` / `nsl pull` over fsspec: a real S3 server (moto) and file:// remotes."""

from __future__ import annotations

from pathlib import Path

import pytest

from nsl import workspace
from nsl.catalog import Catalog
from tests.conftest import run_cli


@pytest.fixture(params=["s3", "file"])
def remote_kind(request):
    return request.param


@pytest.fixture
def remote(remote_kind, request, tmp_path):
    if remote_kind == "s3":
        return request.getfixturevalue("s3") + "/lab"
    return f"file://{tmp_path / 'remote'}"


def test_round_trip_into_an_empty_workspace(publisher, remote, workspace_b, lerobot, capsys):
    from nsl.datasets import api

    v1 = api.open_version("grasp-syn@v1")
    with Catalog() as cat:
        ft = cat.resolve_checkpoint("ckpt:ft-syn")
        base = cat.resolve_checkpoint("ckpt:base-syn")
    assert run_cli("push", "data:grasp-syn@v1", f"{remote}/grasp-syn") == 0
    assert run_cli("push", "ckpt:ft-syn", f"{remote}/ft-syn") == 0
    out = capsys.readouterr().out
    assert "pushed data:grasp-syn@v1" in out and f"pushed ckpt:ft-syn@2 ({ft.short_id})" in out

    home = workspace_b()
    assert run_cli("pull", f"{remote}/grasp-syn") == 0
    assert run_cli("pull", f"{remote}/ft-syn") == 0
    out = capsys.readouterr().out
    assert f"as data:grasp-syn@v1 ({v1.hash})" in out
    pulled = api.open_version("grasp-syn@v1")
    assert pulled.root.parent.parent == home / "datasets"
    assert api.verify("grasp-syn@v1")["hash"] == v1.hash  # bit for bit what was published
    # lerobot opens the pulled copy and sees the same frames
    ds = lerobot("nsl/grasp-syn", root=pulled.root)
    assert ds.num_episodes == v1.num_episodes and ds.num_frames == v1.num_frames
    arrays = pulled.view().read_columns()
    assert float(ds[7]["action"][0]) == pytest.approx(float(arrays["action"][7][0]))

    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:ft-syn")
        assert entry.id == ft.id and entry.parent is None  # the parent was not pulled
        assert [(u.dataset, u.version) for u in entry.data] == [("grasp-syn", 1)]  # pulled: linked by hash
        d = cat.dataset("grasp-syn", 1)
        assert d.hash == v1.hash
    # the lineage shows the origin, the published parent and the data it came from, pulled or not
    assert run_cli("catalog", "lineage", "ckpt:ft-syn") == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].startswith(f"├─ origin: pulled from {remote}/ft-syn (revision {ft.id})")
    assert any(
        line.startswith("├─ data: base-syn@v1 (synthetic, 4 episodes, hash ")
        and "published, not in this workspace), weight 0.5" in line
        for line in lines
    )
    assert f"├─ data: grasp-syn@v1 (synthetic, 5 episodes, pulled from {remote}/grasp-syn at v1), weight 0.5" in lines
    assert any(
        line.startswith(f"└─ from base-syn@2  {base.short_id}  trained for synthetic (published lineage")
        for line in lines
    )
    assert lines[-1] == "   └─ from scratch (no parent)"
    assert any(
        line.startswith("├─ eval: synthetic (test objects) 45.0% [") and line.endswith("(published)") for line in lines
    )
    card = (Path(entry.path) / "README.md").read_text()
    assert f"fine-tuned from `base-syn@2` (`{base.short_id}`)" in card and v1.hash in card
    assert "the evaluations it was published with" in card and "| synthetic | test | 20 | 45.0% |" in card
    # the pulled checkpoint fine-tunes like a local one
    assert (
        run_cli(
            "train",
            "--data",
            "grasp-syn",
            "--init",
            "ckpt:ft-syn",
            "--steps",
            "2",
            "--batch-size",
            "8",
            "--name",
            "ft2",
        )
        == 0
    )
    with Catalog() as cat:
        child = cat.resolve_checkpoint("ckpt:ft2")
        assert child.parent == ft.id
    assert run_cli("catalog", "lineage", "ckpt:ft2") == 0
    out = capsys.readouterr().out
    assert f"origin: pulled from {remote}/ft-syn" in out and "base-syn@2" in out


def test_a_parent_pulled_first_is_linked(publisher, tmp_path, workspace_b, capsys):
    with Catalog() as cat:
        base, ft = cat.resolve_checkpoint("ckpt:base-syn"), cat.resolve_checkpoint("ckpt:ft-syn")
    remote = tmp_path / "remote"
    assert run_cli("push", "ckpt:base-syn", str(remote / "base")) == 0
    assert run_cli("push", "ckpt:ft-syn", str(remote / "ft")) == 0
    workspace_b()
    assert run_cli("pull", str(remote / "base")) == 0 and run_cli("pull", str(remote / "ft")) == 0
    with Catalog() as cat:
        assert [c.id for c in cat.lineage("ckpt:ft-syn")] == [ft.id, base.id]
    capsys.readouterr()
    assert run_cli("catalog", "lineage", "ckpt:ft-syn") == 0
    out = capsys.readouterr().out
    assert f"└─ from base-syn@2  {base.short_id}  trained for synthetic, " in out  # a local node now
    assert "not in this workspace)\n   └─" not in out


def test_a_second_push_of_the_same_version_uploads_nothing(publisher, s3, s3_server, capsys):
    dest = f"{s3}/lab/grasp-syn"
    before = len(s3_server.requests)
    assert run_cli("push", "data:grasp-syn@v1", dest) == 0
    first = s3_server.puts(before)
    from nsl.datasets import api

    files = sorted(api.open_version("grasp-syn@v1").manifest["files"])
    bucket = s3.removeprefix("s3://")
    assert sorted(first) == sorted(
        f"/{bucket}/lab/grasp-syn/v1/{rel}" for rel in [*files, "README.md", "manifest.json"]
    )
    assert first[-1] == f"/{bucket}/lab/grasp-syn/v1/manifest.json"  # the manifest goes last
    capsys.readouterr()
    before = len(s3_server.requests)
    assert run_cli("push", "data:grasp-syn@v1", dest) == 0
    assert s3_server.puts(before) == []
    assert "uploaded nothing (already there)" in capsys.readouterr().out
    # v2 shares most bytes with v1 but goes to its own folder, and a checkpoint pushed twice also sends nothing
    assert run_cli("push", "ckpt:ft-syn", f"{s3}/lab/ft-syn") == 0
    before = len(s3_server.requests)
    assert run_cli("push", "ckpt:ft-syn", f"{s3}/lab/ft-syn") == 0
    assert s3_server.puts(before) == []


def test_an_altered_remote_file_is_refused_by_name(publisher, remote, workspace_b, capsys):
    import fsspec

    assert run_cli("push", "data:grasp-syn@v2", f"{remote}/grasp-syn") == 0
    fs, root = fsspec.core.url_to_fs(f"{remote}/grasp-syn/v2")
    target = f"{root}/data/chunk-000/file-001.parquet"
    data = bytearray(fs.cat_file(target))
    data[len(data) // 2] ^= 0xFF  # one flipped byte, same size
    fs.pipe_file(target, bytes(data))
    home = workspace_b()
    capsys.readouterr()
    assert run_cli("pull", f"{remote}/grasp-syn@v2") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "file data/chunk-000/file-001.parquet does not match the published" in err
    assert not (home / "datasets" / "grasp-syn").exists()
    with Catalog() as cat:
        assert cat.datasets() == []
    fs.rm(target)  # a partial remote: the file is gone
    assert run_cli("pull", f"{remote}/grasp-syn@v2") == 2
    err = capsys.readouterr().err
    assert "file data/chunk-000/file-001.parquet is in the published manifest.json but missing" in err


def test_a_killed_pull_resumes_and_skips_verified_files(publisher, tmp_path, workspace_b, monkeypatch, capsys):
    from nsl.datasets import api
    from nsl.share.fsremote import FsRemote

    remote = f"file://{tmp_path / 'remote'}"
    assert run_cli("push", "data:grasp-syn@v2", f"{remote}/grasp-syn") == 0
    want = api.open_version("grasp-syn@v2")
    workspace_b()
    fetched: list[str] = []
    real_fetch = FsRemote.fetch

    def fetch_then_die(self, rel, dest):
        if len(fetched) == 4:
            raise KeyboardInterrupt  # the process is stopped in the middle of the fifth file
        real_fetch(self, rel, dest)
        fetched.append(rel)

    monkeypatch.setattr(FsRemote, "fetch", fetch_then_die)
    assert run_cli("pull", f"{remote}/grasp-syn") == 130
    assert not (workspace.datasets_dir() / "grasp-syn").exists()  # nothing half-written in the workspace
    first = list(fetched)
    fetched.clear()
    monkeypatch.setattr(FsRemote, "fetch", lambda self, rel, dest: (real_fetch(self, rel, dest), fetched.append(rel)))
    capsys.readouterr()
    assert run_cli("pull", f"{remote}/grasp-syn") == 0
    assert "4 already verified" in capsys.readouterr().out
    assert not set(first) & set(fetched)  # the four verified files were not downloaded again
    assert len(first) + len(fetched) == len(want.manifest["files"])
    assert api.verify("grasp-syn@v2")["hash"] == want.hash
    assert not any((workspace.cache_dir() / "pull").iterdir())  # the staging folder is gone


def test_hugging_face_datasets_reads_the_pushed_frames(publisher, tmp_path, monkeypatch):
    import datasets as hf_datasets
    from nsl.datasets import api

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(hf_datasets.config, "HF_DATASETS_CACHE", tmp_path / "cache")
    assert run_cli("push", "data:grasp-syn@v1", str(tmp_path / "remote")) == 0
    ds = hf_datasets.load_dataset(
        "parquet",
        data_files=str(tmp_path / "remote" / "v1" / "data" / "*" / "*.parquet"),
        split="train",
        cache_dir=str(tmp_path / "cache"),
    )
    want = api.open_version("grasp-syn@v1").view().read_columns()
    assert len(ds) == len(want["index"])
    assert [r[0] if isinstance(r, list) else r for r in ds["index"]] == want["index"].tolist()
    card = (tmp_path / "remote" / "v1" / "README.md").read_text()
    assert "| shift | `synthetic` |" in card and "data_files: data/*/*.parquet" in card


def test_bad_references_and_destinations_fail_in_one_line(publisher, tmp_path, capsys):
    cases = [
        (["push", "grasp-syn@v1", str(tmp_path)], "needs a prefix: data:NAME@vN"),
        (["push", "data:grasp-syn@v1:2", str(tmp_path)], "is a tier; push whole versions"),
        (["push", "data:grasp-syn@v1", "hf://someone/grasp"], "is a model repository"),
        (["push", "ckpt:ft-syn", "hf://datasets/someone/ft"], "is a dataset repository"),
        (["push", "data:grasp-syn@v1", f"{tmp_path}@v3"], "names a revision"),
        (["pull", str(tmp_path / "nothing")], "holds no checkpoint"),
        (["pull", "hf://spaces/a/b"], "is a Space"),
    ]
    for argv, message in cases:
        capsys.readouterr()
        assert run_cli(*argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, (argv, err)
