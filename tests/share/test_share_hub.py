"""`nsl push` / `nsl pull` with the Hugging Face Hub, tested at the ``huggingface_hub`` boundary (a fake Hub)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import nsl
from nsl.catalog import Catalog, origin_of
from nsl.errors import UnknownReferenceError
from tests.conftest import run_cli

REPO = "lab/grasp-syn"


def _changed(new: dict, old: dict) -> list[str]:
    return sorted(rel for rel, f in new["files"].items() if (old["files"].get(rel) or {}).get("sha256") != f["sha256"])


def test_dataset_versions_are_commits_with_tags_that_lerobot_loads(
    publisher, hub, lerobot, workspace_b, tmp_path, capsys
):
    from nsl.datasets import api

    v1, v2 = api.open_version("grasp-syn@v1"), api.open_version("grasp-syn@v2")
    assert run_cli("push", "data:grasp-syn@v1", f"hf://datasets/{REPO}") == 0
    assert hub.uploads == [(REPO, "main", sorted([*v1.manifest["files"], "README.md", "manifest.json"]))]
    repo = hub.repos[("dataset", REPO)]
    c1 = repo.branches["main"]
    assert repo.tags == {"v1": c1, "v3.0": c1}
    # v2 sends only the files whose content differs from v1's (new data, updated metadata), then moves v3.0
    assert run_cli("push", "data:grasp-syn@v2", f"hf://datasets/{REPO}") == 0
    changed = _changed(v2.manifest, v1.manifest)
    assert [f for f in changed if f.startswith("data/")] == ["data/chunk-000/file-003.parquet"]  # the new one
    assert hub.uploads[1] == (REPO, "main", sorted([*changed, "README.md", "manifest.json"]))
    c2 = repo.branches["main"]
    assert repo.tags == {"v1": c1, "v2": c2, "v3.0": c2}
    card = repo.commits[c2]["README.md"].decode()
    assert "- LeRobot" in card and v2.hash in card and "| episodes | 7 (" in card and "| policy | `none` |" in card
    capsys.readouterr()
    assert run_cli("push", "data:grasp-syn@v2", f"hf://datasets/{REPO}") == 0  # again: no commit at all
    assert len(hub.uploads) == 2 and "uploaded nothing" in capsys.readouterr().out
    # lerobot's own hub loading (get_safe_version -> tag v3.0, snapshot_download) opens the pushed dataset
    ds = lerobot(REPO, root=tmp_path / "lerobot-cache")
    assert ds.meta.revision == "v3.0" and ds.num_episodes == v2.num_episodes and ds.num_frames == v2.num_frames

    workspace_b()
    hub.downloads.clear()
    assert run_cli("pull", f"hf://datasets/{REPO}@v1") == 0
    assert sorted(f for _, f, rev in hub.downloads if rev == c1) == sorted(["manifest.json", *v1.manifest["files"]])
    assert {rev for _, _, rev in hub.downloads} == {c1}  # every file at the commit the tag named
    assert api.verify("grasp-syn@v1")["hash"] == v1.hash
    assert run_cli("pull", f"hf://datasets/{REPO}") == 0  # main: the newest push, v2
    assert api.verify("grasp-syn@v2")["hash"] == v2.hash
    with Catalog() as cat:
        o = origin_of(cat, "dataset", "grasp-syn@v2")
    assert (o.url, o.revision, o.published["version"]) == (f"hf://datasets/{REPO}", c2, 2)


def test_a_checkpoint_is_a_model_repo_and_pulls_with_its_origin(publisher, hub, workspace_b, capsys, monkeypatch):
    token = "hf_" + "Zx9" * 12
    monkeypatch.setenv("HF_TOKEN", token)  # the standard way; nsl must never show or store it
    with Catalog() as cat:
        ft = cat.resolve_checkpoint("ckpt:ft-syn")
    assert run_cli("push", "ckpt:ft-syn", "hf://lab/ft-syn") == 0
    assert hub.uploads == [("lab/ft-syn", "main", ["README.md", "config.json", "manifest.json", "model.safetensors"])]
    repo = hub.repos[("model", "lab/ft-syn")]
    files = repo.commits[repo.branches["main"]]
    card = files["README.md"].decode()
    assert "library_name: nsl" in card and "grasp success rate" in card and "45.0%" in card
    assert "`base-syn@2`" in card and "grasp-syn@v1" in card
    assert run_cli("push", "ckpt:ft-syn", "hf://lab/ft-syn") == 0
    assert len(hub.uploads) == 1  # nothing changed: no commit

    workspace_b()
    hub.downloads.clear()
    capsys.readouterr()
    assert run_cli("pull", "hf://lab/ft-syn", "--as", "theirs") == 0
    commit = repo.branches["main"]
    assert sorted(hub.downloads) == sorted(
        ("lab/ft-syn", f, commit) for f in ("manifest.json", "model.safetensors", "config.json")
    )
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:theirs")
        o = origin_of(cat, "checkpoint", entry.id)
    assert entry.id == ft.id and (entry.name, entry.step) == ("theirs", ft.step)
    assert (o.url, o.revision) == ("hf://lab/ft-syn", commit) and o.lineage[1]["name"] == "base-syn"
    assert run_cli("pull", "hf://lab/ft-syn") == 0  # the same checkpoint again: nothing new is registered
    captured = capsys.readouterr()
    assert "already in the catalog" in captured.out
    home = workspace_b()
    stored = [p.read_bytes() for p in home.rglob("*") if p.is_file()] + list(files.values())
    assert token not in captured.out + captured.err and not any(token.encode() in b for b in stored)


def test_an_altered_hub_file_is_refused_and_a_killed_pull_resumes(publisher, hub, workspace_b, capsys):
    assert run_cli("push", "ckpt:ft-syn", "hf://lab/ft-syn") == 0
    repo = hub.repos[("model", "lab/ft-syn")]
    files = repo.commits[repo.branches["main"]]
    good = files["config.json"]
    files["config.json"] = good.replace(b'"step": 2', b'"step": 3')  # edited on the Hub, manifest left alone
    home = workspace_b()
    capsys.readouterr()
    assert run_cli("pull", "hf://lab/ft-syn") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "file config.json does not match the published manifest.json" in err
    assert not (home / "checkpoints").exists()
    files["config.json"] = good

    def die_on_weights(filename):
        if filename == "model.safetensors":  # files come in sorted order: config.json is verified by then
            raise KeyboardInterrupt

    hub.fail_download = die_on_weights
    assert run_cli("pull", "hf://lab/ft-syn") == 130
    hub.fail_download = None
    hub.downloads.clear()
    assert run_cli("pull", "hf://lab/ft-syn") == 0
    assert "1 file(s) downloaded, 1 already verified" in capsys.readouterr().out
    assert sorted(f for _, f, _ in hub.downloads) == ["manifest.json", "model.safetensors"]


@pytest.mark.parametrize(
    "src, message",
    [
        ("hf://datasets/lab/nope", "does not exist or this account may not access it"),
        (f"hf://datasets/{REPO}@v9", "has no revision 'v9'"),
    ],
)
def test_hub_errors_are_one_line(publisher, hub, src, message, capsys):
    assert run_cli("push", "data:grasp-syn@v1", f"hf://datasets/{REPO}") == 0
    capsys.readouterr()
    assert run_cli("pull", src) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err


# ----------------------------------------------- nsl.load_policy: a folder, a catalog reference or a pushed repo


@pytest.fixture
def observation():
    """One LeRobot observation batch from the 16x16 task (the publisher's tiny networks see 16x16 frames)."""
    from lerobot.envs.utils import preprocess_observation

    from nsl.collectors import GraspEnv

    env = GraspEnv(image_size=16, obs_type="pixels_agent_pos")
    try:
        obs, _ = env.reset(seed=3)
    finally:
        env.close()
    return obs, preprocess_observation(obs)


def test_load_policy_from_a_folder_a_catalog_reference_and_pushed_repos(publisher, hub, s3, workspace_b, observation):
    """One call loads a checkpoint as ``from_pretrained`` does; it acts through nsl's call and LeRobot's."""
    raw, batch = observation
    with Catalog() as cat:
        entry = cat.resolve_checkpoint("ckpt:ft-syn")
    by_ref = nsl.load_policy("ckpt:ft-syn")
    action = by_ref.select_action(batch)
    assert isinstance(action, torch.Tensor) and action.shape == (1, 6) and action.dtype == torch.float32
    assert action.abs().max() <= 1.0
    by_folder = nsl.load_policy(entry.path)
    assert torch.equal(by_folder.select_action(batch), action)  # same checkpoint, same seed: the same action
    by_ref.reset()
    assert torch.equal(by_ref.select_action(batch), action)  # reset() starts the draws over
    # nsl's own call, on nsl's observation keys
    nsl_obs = {"image": raw["pixels"][None], "state": raw["agent_pos"][None]}
    assert by_folder(nsl_obs, rngs=[np.random.default_rng(0)]).shape == (1, 6)
    assert by_folder.describe()["checkpoint_id"] == entry.id

    assert run_cli("push", "ckpt:ft-syn", "hf://lab/ft-syn") == 0
    assert run_cli("push", "ckpt:ft-syn", f"{s3}/lab/ft-syn") == 0
    home = workspace_b()  # a lab with an empty workspace loads them by repo id and URL
    for source in ("lab/ft-syn", "hf://lab/ft-syn@main", f"{s3}/lab/ft-syn"):
        pulled = nsl.load_policy(source)
        assert pulled.describe()["checkpoint_id"] == entry.id, source
        assert torch.equal(pulled.select_action(batch), action), source
    assert (home / "cache" / "policies").is_dir()
    with Catalog() as cat:  # verified into the cache, not catalogued
        with pytest.raises(UnknownReferenceError):
            cat.resolve_checkpoint("ckpt:ft-syn")


def test_load_policy_of_an_unknown_source_is_one_line(tmp_path):
    with pytest.raises(UnknownReferenceError, match="neither a folder, a catalog reference"):
        nsl.load_policy(tmp_path / "missing" / "deeper")
