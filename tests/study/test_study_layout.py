"""nsl.study is a wiring layer: the five folders never import it, and it reaches nsl.commands._refs in one module only."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("collectors", "datasets", "learners", "eval", "catalog")


def test_the_five_folders_never_import_the_study():
    pattern = re.compile(r"^\s*(from|import)\s+(nsl\.study|study)\b", re.M)
    offenders = [str(p.relative_to(ROOT)) for f in FOLDERS for p in (ROOT / f).rglob("*.py")
                 if pattern.search(p.read_text())]
    assert offenders == []


def test_reference_glue_is_imported_by_the_adapter_only():
    users = sorted(p.name for p in (ROOT / "study").glob("*.py") if "nsl.commands._refs" in p.read_text())
    assert users == ["actions.py"]
