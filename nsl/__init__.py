"""nsl ("never stop learning"): offline continual learning for vision-based grasping.

The import package ``nsl`` has five subpackages that live in folders at the
repository root: ``nsl.collectors``, ``nsl.datasets``, ``nsl.learners``,
``nsl.eval`` and ``nsl.catalog``.  An installed wheel holds them under
``nsl/``; in a source checkout (editable install, or ``python -m`` from the
root) this file appends the repository root to ``__path__`` so the same names
resolve to the root folders.

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
