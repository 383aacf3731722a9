"""The package layout keeps Hugging Face ``datasets`` (and so lerobot) importable."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_hf_datasets_not_shadowed_in_this_process():
    # Under `python -m pytest` from the repo root, the root is on sys.path.
    import datasets

    assert Path(datasets.__file__).resolve().parent != ROOT / "datasets"
    assert hasattr(datasets, "Dataset") and hasattr(datasets, "load_dataset")
    import nsl.datasets

    assert [Path(p).resolve() for p in nsl.datasets.__path__] == [ROOT / "datasets"]


def _run(code: str, cwd: Path) -> str:
    out = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_imports_from_repo_root_and_elsewhere(tmp_path):
    code = (
        "import sys; sys.path.insert(0, '');"
        "import datasets, lerobot.datasets.lerobot_dataset, nsl.collectors, nsl.datasets, nsl.eval;"
        "print(datasets.__file__); print(nsl.collectors.__file__)"
    )
    for cwd in (ROOT, tmp_path):
        hf, collectors = _run(code, cwd).splitlines()
        assert "site-packages" in hf, f"Hugging Face datasets shadowed from {cwd}: {hf}"
        assert Path(collectors).resolve() == ROOT / "collectors" / "__init__.py"


def test_wheel_contains_every_subpackage_and_the_api(tmp_path):
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp_path),
            str(ROOT),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    wheel = next(tmp_path.glob("nsl-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "nsl/collectors/env.py" in names and "nsl/eval/success.py" in names
    assert "nsl/catalog/__init__.py" in names and "nsl/learners/__init__.py" in names
    assert "nsl/study/driver.py" in names and "nsl/study/plans/small.toml" in names
    assert "nsl/curriculum/tree.py" in names and "nsl/study/plans/transfer-small.toml" in names
    assert "nsl/services/train.py" in names and "nsl/api.py" in names and "nsl/share/transports.py" in names
    assert not any(n.startswith("datasets/") for n in names), "a top-level datasets/ would shadow Hugging Face's"
