"""The layout rules, read from every module's imports with ``ast``.

* The five folders import only the shared core (``nsl/*.py`` but the CLI) and
  themselves; ``eval/`` may also import ``collectors/``.
* The core imports none of the folders and nothing of the CLI.
* The layers above them import only what is below (:data:`LAYERS`): ``nsl.curriculum`` and
  ``nsl.share`` the core alone, ``nsl.cluster`` the collectors; ``nsl.services`` (one function per
  user action) the folders, share, cluster and curriculum; ``nsl.study`` the services too; the public
  ``nsl.api`` the study too.  None of them imports the command line.
* Nothing outside the command line imports ``nsl.commands`` (scripts included).
* Every third-party package the code imports is declared in pyproject.toml.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("collectors", "datasets", "learners", "eval", "catalog")
ALLOWED_FOLDERS = {"eval": {"collectors"}}
CLI = ("nsl.cli", "nsl.__main__", "nsl.commands", "nsl.bench")
CORE = sorted(
    f"nsl.{p.stem}" for p in (ROOT / "nsl").glob("*.py") if p.stem not in ("__init__", "__main__", "cli", "api")
)
_FIVE = {f"nsl.{f}" for f in FOLDERS}
# package -> the nsl packages it may import besides the core and itself
LAYERS = {
    "curriculum": set(),
    "share": set(),
    "cluster": {"nsl.collectors"},
    "services": _FIVE | {"nsl.share", "nsl.cluster", "nsl.curriculum"},
    "study": _FIVE | {"nsl.services", "nsl.share", "nsl.cluster", "nsl.curriculum"},
}
API_ALLOWED = _FIVE | {"nsl.services", "nsl.study", "nsl.share", "nsl.cluster", "nsl.curriculum"}


def _modules(folder: Path, package: str) -> list[tuple[str, Path]]:
    out = []
    for path in sorted(folder.rglob("*.py")):
        rel = path.relative_to(folder).with_suffix("")
        parts = [p for p in rel.parts if p != "__init__"]
        out.append((".".join([package, *parts]), path))
    return out


def _imports(module: str, path: Path) -> list[str]:
    """Absolute names of everything ``module`` imports (at any depth: lazy imports count)."""
    is_package = path.name == "__init__.py"
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")[: len(module.split(".")) - node.level + (1 if is_package else 0)]
                parent = ".".join(base + ([node.module] if node.module else []))
            else:
                parent = node.module or ""
            names.append(parent)
            names += [f"{parent}.{a.name}" for a in node.names]  # `from nsl import workspace` names a module
    return names


def _nsl_targets(names: list[str]) -> set[str]:
    """The nsl modules or folders named: nsl.X for the core, nsl.FOLDER for a folder, nsl.commands for the CLI."""
    out = set()
    for name in names:
        parts = name.split(".")
        if parts[0] != "nsl" or len(parts) == 1:
            continue
        out.add(".".join(parts[:2]))
    return out


FOLDER_MODULES = [(f, m, p) for f in FOLDERS for m, p in _modules(ROOT / f, f"nsl.{f}")]
LAYER_MODULES = [(f, m, p) for f in LAYERS for m, p in _modules(ROOT / f, f"nsl.{f}")]
CORE_MODULES = [("nsl", ROOT / "nsl" / "__init__.py")] + [(m, ROOT / "nsl" / f"{m.split('.')[1]}.py") for m in CORE]


def _core_names() -> set[str]:
    """What ``from nsl import X`` may name: the core modules and the package's own attributes."""
    return set(CORE) | {"nsl.__version__", "nsl.code_version"}


@pytest.mark.parametrize("folder, module, path", FOLDER_MODULES, ids=[m for _, m, _ in FOLDER_MODULES])
def test_folders_import_only_the_core(folder, module, path):
    allowed = _core_names() | {f"nsl.{folder}"} | {f"nsl.{f}" for f in ALLOWED_FOLDERS.get(folder, ())}
    bad = sorted(t for t in _nsl_targets(_imports(module, path)) if t not in allowed)
    assert not bad, f"{path.relative_to(ROOT)} imports {bad}; a folder may import only {sorted(allowed)}"


@pytest.mark.parametrize("package, module, path", LAYER_MODULES, ids=[m for _, m, _ in LAYER_MODULES])
def test_each_layer_imports_only_what_is_below_it(package, module, path):
    allowed = _core_names() | {f"nsl.{package}"} | LAYERS[package]
    bad = sorted(t for t in _nsl_targets(_imports(module, path)) if t not in allowed)
    assert not bad, f"{path.relative_to(ROOT)} imports {bad}; nsl.{package} may import only {sorted(allowed)}"


def test_every_layer_is_checked():
    found = {m for _, m, _ in LAYER_MODULES}
    assert {
        "nsl.curriculum.tree",
        "nsl.services.train",
        "nsl.study.actions",
        "nsl.share.transfer",
        "nsl.cluster.executor",
    } <= found
    assert all((ROOT / f).is_dir() for f in LAYERS)


def test_the_api_imports_no_command_line():
    path = ROOT / "nsl" / "api.py"
    bad = sorted(
        t
        for t in _nsl_targets(_imports("nsl.api", path))
        if t not in _core_names() | API_ALLOWED | {"nsl.api", "nsl._API"}
    )
    assert not bad, f"nsl/api.py imports {bad}; the API sits below the command line"


def _product_files():
    """Every Python file outside the command line and the tests: the folders, the layers, the core, scripts."""
    for folder in (*FOLDERS, *LAYERS, "scripts"):
        yield from sorted((ROOT / folder).rglob("*.py"))
    yield from (ROOT / "nsl" / f"{m.split('.')[1]}.py" for m in (*CORE, "nsl.api"))


def test_nothing_outside_the_command_line_imports_it():
    offenders = []
    for path in _product_files():
        names = _imports("x.y", path)
        if any(n == "nsl.commands" or n.startswith(("nsl.commands.", "nsl.cli", "nsl.bench")) for n in names):
            offenders.append(str(path.relative_to(ROOT)))
    assert offenders == [], f"{offenders} import the command line; call nsl's API or nsl.services instead"


def test_the_checker_finds_an_upward_import(tmp_path):
    sample = tmp_path / "mod.py"
    sample.write_text("def f():\n    from nsl.commands.train import run\n    import nsl.api\n")
    assert _nsl_targets(_imports("nsl.study.mod", sample)) == {"nsl.commands", "nsl.api"}


@pytest.mark.parametrize("module, path", CORE_MODULES, ids=[m for m, _ in CORE_MODULES])
def test_the_core_imports_no_folder_and_no_cli(module, path):
    targets = _nsl_targets(_imports(module, path))
    bad = sorted(t for t in targets if t in {f"nsl.{f}" for f in FOLDERS} or t.startswith(CLI))
    assert not bad, f"{path.relative_to(ROOT)} imports {bad}; the core must stand alone"
    assert path.is_file()


def test_the_core_is_what_the_layout_says():
    assert {"nsl.errors", "nsl.keys", "nsl.workspace", "nsl.version"} <= set(CORE)
    assert "nsl.resolve" not in CORE and "nsl.doctor" not in CORE  # CLI glue lives under nsl.commands


def test_the_checker_sees_relative_and_lazy_imports(tmp_path):
    sample = tmp_path / "mod.py"
    sample.write_text("from ..learners import train\n\ndef f():\n    from nsl import catalog\n")
    assert _nsl_targets(_imports("nsl.eval.mod", sample)) == {"nsl.learners", "nsl.catalog"}


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def test_every_imported_package_is_declared():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    specs = list(project["dependencies"]) + [d for ds in project.get("optional-dependencies", {}).values() for d in ds]
    declared = {_normal(re.split(r"[<>=!~;\[ ]", d, maxsplit=1)[0]) for d in specs}
    dists = packages_distributions()
    missing = {}
    for folder in ("nsl", *FOLDERS, *LAYERS, "scripts"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            module = ".".join(("x", *path.relative_to(ROOT).with_suffix("").parts))  # relative imports stay in x
            for name in _imports(module, path):
                top = name.split(".")[0]
                if not top or top in sys.stdlib_module_names or top in ("nsl", "x", "__future__"):
                    continue
                if not any(_normal(d) in declared for d in dists.get(top, [top])):
                    missing.setdefault(top, str(path.relative_to(ROOT)))
    assert not missing, f"imported but not declared in pyproject.toml: {missing}"
