"""No module imports a module that imports it back, directly or around a longer loop, lazily or not.

Imports are read with ``ast`` at any depth (an import inside a function counts).  The folders are
subpackages of ``nsl`` (``share/`` is ``nsl.share``, ...), so relative imports resolve against them.
An edge goes to the module an import names: ``from . import actions`` names ``nsl.study.actions``,
``from .units import Unit`` names ``nsl.study.units``, ``from nsl.collectors import ENV_VERSION``
names the package ``nsl.collectors`` (its ``__init__``).  The parent package that Python imports
before any submodule is not an edge (every submodule would otherwise close a loop with its
package's ``__init__``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = (
    "share",
    "cluster",
    "study",
    "curriculum",
    "collectors",
    "datasets",
    "learners",
    "eval",
    "catalog",
    "services",
)
CORE = tuple(sorted(p.stem for p in (ROOT / "nsl").glob("*.py") if p.stem not in ("__init__", "__main__", "cli")))


def _modules() -> dict[str, Path]:
    out = {f"nsl.{stem}": ROOT / "nsl" / f"{stem}.py" for stem in CORE}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = [p for p in path.relative_to(ROOT / package).with_suffix("").parts if p != "__init__"]
            out[".".join(["nsl", package, *parts])] = path
    return out


MODULES = _modules()


def imported(module: str, path: Path) -> set[str]:
    """The modules of MODULES that ``module`` imports anywhere in its source."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                parent = ".".join(base + ([node.module] if node.module else []))
            else:
                parent = node.module or ""
            subs = [f"{parent}.{a.name}" for a in node.names if f"{parent}.{a.name}" in MODULES]
            names = subs if len(subs) == len(node.names) else [parent, *subs]  # `from pkg import NAME`: pkg
        else:
            continue
        out.update(n for n in names if n in MODULES and n != module)
    return out


def graph() -> nx.DiGraph:
    g = nx.DiGraph()
    for module, path in MODULES.items():
        g.add_node(module)
        g.add_edges_from((module, target) for target in imported(module, path))
    return g


def test_the_import_reader_resolves_relative_and_lazy_imports(tmp_path):
    src = tmp_path / "x.py"
    src.write_text(
        "from . import transfer\nfrom .remotes import Location\n"
        "def f():\n    from ..collectors import GYM_ID\n    import nsl.share.hub\n"
    )
    assert imported("nsl.share.x", src) == {
        "nsl.share.transfer",
        "nsl.share.remotes",
        "nsl.collectors",
        "nsl.share.hub",
    }
    pkg = tmp_path / "__init__.py"
    pkg.write_text("from .tasks import get\n")
    assert imported("nsl.cluster", pkg) == {"nsl.cluster.tasks"}


def test_the_graph_has_the_known_edges():
    g = graph()
    assert g.has_edge("nsl.share.transfer", "nsl.share.transports")
    assert g.has_edge("nsl.share.transports", "nsl.share.fsremote")  # lazy, inside open_remote
    assert g.has_edge("nsl.cluster.executor", "nsl.cluster.collect")  # lazy, inside RayExecutor.__init__
    assert g.has_edge("nsl.cluster.collect", "nsl.collectors")  # lazy, the package
    assert g.has_edge("nsl.study.driver", "nsl.study.actions")  # `from . import actions`


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    g = graph()
    mine = [m for m in g if m == f"nsl.{package}" or m.startswith(f"nsl.{package}.")]
    cycles = [c for c in nx.simple_cycles(g) if any(m in mine for m in c)]
    assert not cycles, "import cycles: " + "; ".join(" -> ".join([*c, c[0]]) for c in cycles)
