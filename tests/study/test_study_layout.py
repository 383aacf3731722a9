"""nsl.study is a wiring layer: the five folders never import it, and it never reaches the command line."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
FOLDERS = ("collectors", "datasets", "learners", "eval", "catalog")


def test_the_five_folders_never_import_the_study():
    pattern = re.compile(r"^\s*(from|import)\s+(nsl\.study|study)\b", re.M)
    offenders = [
        str(p.relative_to(ROOT)) for f in FOLDERS for p in (ROOT / f).rglob("*.py") if pattern.search(p.read_text())
    ]
    assert offenders == []


def test_the_study_calls_the_services_not_the_commands():
    users = sorted(p.name for p in (ROOT / "study").glob("*.py") if "nsl.commands" in p.read_text())
    assert users == []
    services = sorted(p.name for p in (ROOT / "study").glob("*.py") if "nsl.services" in p.read_text())
    assert "actions.py" in services
