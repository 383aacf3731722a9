"""nsl ("never stop learning"): offline continual learning for vision-based grasping.

The import package ``nsl`` has five subpackages that live in folders at the
repository root: ``nsl.collectors``, ``nsl.datasets``, ``nsl.learners``,
``nsl.eval`` and ``nsl.catalog``.  An installed wheel holds them under
``nsl/``; in a source checkout (editable install, or ``python -m`` from the
root) this file appends the repository root to ``__path__`` so the same names
resolve to the root folders.

The modules directly in ``nsl/`` are the small shared core the folders may
import: ``errors`` (the exception family), ``keys`` (batch keys and
dimensions), ``workspace`` (paths and atomic writes), ``version``,
``refs`` (names and dataset references), ``stats`` (the Wilson interval) and
``checkpoint_format`` (the checkpoint folder format).  The command line
(``cli``, ``commands/``, ``bench/``) wires the folders together; the core
imports neither the folders nor the CLI (``tests/test_import_graph.py``).

``datasets/`` deliberately has no ``__init__.py``: a regular package named
``datasets`` at the repository root would shadow Hugging Face's ``datasets``
(and so break lerobot) whenever the root is on ``sys.path``.
"""

from __future__ import annotations

import os as _os

from nsl.version import __version__, code_version  # noqa: F401  (re-exported)

_root = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if _os.path.isfile(_os.path.join(_root, "pyproject.toml")) and _os.path.isdir(
    _os.path.join(_root, "collectors")
):
    __path__.append(_root)  # type: ignore[name-defined]  # noqa: F821
