"""verify, rm and gc against real files in the workspace."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from catalog_factories import make_checkpoint, make_dataset, manifest_hasher

from nsl import workspace
from nsl.catalog import CONFIG_FILE, WEIGHTS_FILE, Catalog, format_lineage, gc_apply, gc_plan, remove, verify
from nsl.errors import ConfigError, CorruptDataError


@pytest.fixture
def cat():
    with Catalog() as c:
        yield c


def _age(path: Path, seconds: float = 7200) -> None:
    """Backdate a file or folder tree, as if written ``seconds`` ago."""
    t = time.time() - seconds
    for dirpath, dirnames, filenames in os.walk(path) if path.is_dir() else []:
        for n in dirnames + filenames:
            os.utime(os.path.join(dirpath, n), (t, t))
    os.utime(path, (t, t))


def test_verify_detects_an_altered_checkpoint_file(cat, tmp_path):
    data = make_dataset(cat, "grasp-base")
    ck = make_checkpoint(cat, tmp_path, "base", 100, 0.5, data=[cat.resolve_data("data:grasp-base").use()])
    report = verify(cat, dataset_hasher=manifest_hasher)
    assert report.ok and (report.checkpoints, report.datasets) == (1, 1)
    weights = Path(ck.path) / WEIGHTS_FILE
    raw = bytearray(weights.read_bytes())
    raw[-1] ^= 0x01  # one flipped bit in the last float
    weights.write_bytes(bytes(raw))
    (Path(ck.path) / CONFIG_FILE).unlink()
    report = verify(cat)
    assert not report.ok
    details = sorted(str(p) for p in report.problems)
    assert details[0].startswith(f"ckpt:base@100: {ck.path}/{CONFIG_FILE}: missing")
    assert details[1].startswith(f"ckpt:base@100: {weights}: altered (sha256 ")
    assert verify(cat, ["data:grasp-base"]).ok  # only the dataset: still fine
    (Path(data.path) / "data.bin").write_bytes(b"tampered")
    (Path(data.path) / "extra.parquet").write_bytes(b"new")
    report = verify(cat, ["data:grasp-base@v1"], dataset_hasher=manifest_hasher)
    details = [p.detail for p in report.problems]
    assert details[0].startswith("altered") and details[1] == "added since registration"
    assert details[2].startswith("content hash") and "differs from the registered" in details[2]

    def strict_hasher(root: Path) -> str:  # a datasets check that raises on the first bad file
        raise CorruptDataError(f"{root}/data.bin is altered")

    report = verify(cat, ["data:grasp-base"], dataset_hasher=strict_hasher)
    assert report.problems[-1].detail == f"{data.path}/data.bin is altered"


def test_rm_refuses_dependents_unless_forced(cat, tmp_path):
    make_dataset(cat, "grasp-base")
    base = make_checkpoint(cat, tmp_path, "base", 100, 0.0, data=[cat.resolve_data("data:grasp-base").use()])
    child = make_checkpoint(cat, tmp_path, "harsh", 10, 1.0, parent=base.id)
    cat.add_evaluation(base.id, "base", episodes=10, successes=7, seed=0)
    cat.tag("prod", base.id)
    with pytest.raises(
        ConfigError,
        match=r"ckpt:base@100 .* has dependents: 1 child checkpoint\(s\) \(harsh@10\); "
        r"1 evaluation\(s\); tag\(s\) prod; .* --force",
    ):
        remove(cat, "ckpt:base")
    with pytest.raises(ConfigError, match=r"data:grasp-base@v1 was used to train 1 checkpoint\(s\) \(base@100\)"):
        remove(cat, "data:grasp-base@v1")
    with pytest.raises(ConfigError, match="say which version"):
        remove(cat, "data:grasp-base")
    assert Path(base.path).is_dir()
    removed = remove(cat, "ckpt:base@100", force=True)
    assert removed[0].startswith("checkpoint base@100") and "tag prod" in removed and "1 evaluation(s)" in removed
    assert not Path(base.path).exists() and cat.evaluations(base.id) == [] and "prod" not in cat.tags()
    assert f"└─ from {base.id[:12]} (removed from the catalog)" in format_lineage(cat, "ckpt:harsh")
    assert remove(cat, "ckpt:harsh") == [f"checkpoint harsh@10 ({child.short_id})", f"folder {child.path}"]
    ds = cat.dataset("grasp-base")
    assert remove(cat, "data:grasp-base@v1", delete_files=False) == ["dataset grasp-base@v1"]
    assert Path(ds.path).is_dir() and cat.datasets() == []


def test_gc_removes_only_unreferenced_and_stale_files(cat, tmp_path):
    make_dataset(cat, "grasp-base")
    kept = make_checkpoint(cat, tmp_path, "base", 100, 0.0)
    orphan = workspace.checkpoints_dir() / "base" / "00000200-deadbeef0000"
    orphan.mkdir(parents=True)
    (orphan / WEIGHTS_FILE).write_bytes(b"x" * 100)
    stale_tmp = workspace.checkpoints_dir() / "base" / ".tmp-00000300-abc"
    stale_tmp.mkdir()
    (stale_tmp / WEIGHTS_FILE).write_bytes(b"y" * 10)
    half_written = Path(kept.path) / ".README.md.x1y2.tmp"
    half_written.write_text("partial")
    unregistered = workspace.datasets_dir() / "grasp-base" / "v2"  # datasets own their folders: never collected
    unregistered.mkdir()
    (unregistered / "data.bin").write_bytes(b"z" * 5)
    staging = workspace.datasets_dir() / "grasp-base" / ".staging"  # a paused, resumable collection
    staging.mkdir()
    (staging / "plan.json").write_text("{}")
    fresh = workspace.checkpoints_dir() / "base" / "00000400-fresh0000000"  # being written right now
    fresh.mkdir()
    (fresh / WEIGHTS_FILE).write_bytes(b"w")
    for p in (orphan, stale_tmp, half_written, unregistered, staging):
        _age(p)
    plan = {item.path: item.reason for item in gc_plan(cat)}
    assert plan == {
        orphan: "unregistered checkpoint folder",
        stale_tmp: "stale temporary folder",
        half_written: "stale temporary file",
    }
    assert fresh in {i.path for i in gc_plan(cat, min_age=0)}
    assert gc_apply(gc_plan(cat)) == 100 + 10 + len("partial")
    assert not any(p.exists() for p in plan)
    assert fresh.exists() and unregistered.exists() and staging.exists()
    assert verify(cat).ok and cat.dataset("grasp-base").version == 1
