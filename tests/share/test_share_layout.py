"""`nsl.share` is its own subpackage: it depends on nsl's core only, and the five folders never import it."""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from nsl.errors import ConfigError
from nsl.share import parse_remote

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("collectors", "datasets", "learners", "eval", "catalog")


def test_share_is_packaged_and_imports_no_folder():
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "nsl.share" in conf["packages"] and conf["package-dir"]["nsl.share"] == "share"
    code = (
        "import sys, nsl.share; "
        f"print(sorted(m for m in sys.modules if m.split('.')[:2] in [['nsl', f] for f in {FOLDERS!r}]))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
    for folder in FOLDERS:
        for path in (ROOT / folder).rglob("*.py"):
            assert not re.search(r"\bnsl\.share\b|from \.\.share", path.read_text()), path


@pytest.mark.parametrize(
    "text, url, revision, repo",
    [
        ("hf://datasets/lab/grasp@v2", "hf://datasets/lab/grasp", "v2", ("lab/grasp", "dataset")),
        ("hf://lab/ft-harsh", "hf://lab/ft-harsh", None, ("lab/ft-harsh", "model")),
        ("hf://models/lab/ft@main", "hf://lab/ft", "main", ("lab/ft", "model")),
        ("s3://bucket/shared/grasp@v1", "s3://bucket/shared/grasp", "v1", (None, None)),
        ("file:///srv/my@data/grasp/", "file:///srv/my@data/grasp", None, (None, None)),
    ],
)
def test_remote_addresses(text, url, revision, repo):
    loc = parse_remote(text)
    assert (loc.url, loc.revision, (loc.repo_id, loc.repo_type)) == (url, revision, repo)


def test_plain_paths_become_file_urls_and_name_the_item(tmp_path):
    loc = parse_remote(str(tmp_path / "grasp-harsh" / "v3"))
    assert loc.url == f"file://{tmp_path}/grasp-harsh/v3" and loc.name == "grasp-harsh"
    with pytest.raises(ConfigError, match="not a Hub repository"):
        parse_remote("hf://lab")


def test_credentials_in_a_url_are_refused_without_echoing_them():
    with pytest.raises(ConfigError) as e:
        parse_remote("s3://AKIAXX:hunter2@bucket/grasp")
    assert "hunter2" not in str(e.value) and "carries credentials" in str(e.value)
