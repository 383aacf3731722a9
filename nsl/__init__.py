"""nsl ("never stop learning"): offline continual learning for vision-based grasping.

The Python API is this package's functions (``nsl.api``, loaded on first use)::

    nsl.collect  nsl.train  nsl.evaluate  nsl.report  nsl.continual  nsl.online  nsl.efficiency  nsl.push  nsl.pull
    nsl.compare  nsl.features  nsl.study_run  nsl.study_status  nsl.study_report  nsl.transfer_run  nsl.build_curriculum
    nsl.load_policy (a checkpoint from a folder, a catalog reference or the Hub, with LeRobot's select_action)

with their configs (``nsl.CollectConfig``, ``nsl.TrainOptions``, ...) and the
named scene seeds (``nsl.SELECTION_SCENES``, ...); ``docs/python.md`` walks
through them.  The ``nsl`` command line calls the same functions.

The subpackages live in folders at the repository root, in layers (each
imports only those below it; ``tests/test_import_graph.py`` checks it):

* the core, the modules directly in ``nsl/``: ``errors``, ``keys``,
  ``workspace``, ``version``, ``refs``, ``scenes``, ``stats``, ``checkpoint_format``;
* the five folders, which import only the core (``nsl.eval`` may drive
  ``nsl.collectors``): ``nsl.collectors``, ``nsl.datasets``,
  ``nsl.learners``, ``nsl.eval``, ``nsl.catalog``;
* ``nsl.curriculum`` (graph maths on the core alone), ``nsl.share`` (remotes)
  and ``nsl.cluster`` (Ray);
* ``nsl.services``, one function per user action over the folders;
* ``nsl.study``, the study and transfer plans run as units of those services;
* ``nsl.api`` and the command line (``cli``, ``commands/``, ``bench/``).

An installed wheel holds the folders under ``nsl/``; in a source checkout
(editable install, or ``python -m`` from the root) this file appends the
repository root to ``__path__`` so the same names resolve to the root folders.

``datasets/`` deliberately has no ``__init__.py``: a regular package named
``datasets`` at the repository root would shadow Hugging Face's ``datasets``
(and so break lerobot) whenever the root is on ``sys.path``.
"""

from __future__ import annotations

import os as _os
from typing import TYPE_CHECKING

from nsl.lazy import lazy_exports

if TYPE_CHECKING:
    from nsl.version import __version__, code_version  # noqa: F401  (re-exported, read on first use)

_root = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if _os.path.isfile(_os.path.join(_root, "pyproject.toml")) and _os.path.isdir(_os.path.join(_root, "collectors")):
    __path__.append(_root)  # type: ignore[name-defined]  # noqa: F821

_API = (
    "CollectConfig",
    "ContinualConfig",
    "Curriculum",
    "EfficiencyConfig",
    "EvaluateOptions",
    "FeaturesConfig",
    "OnlineConfig",
    "StudyRun",
    "TrainOptions",
    "EVAL_SCENES",
    "FINAL_REPORTING_SCENES",
    "REPORTING_SCENES",
    "SELECTION_SCENES",
    "build_curriculum",
    "collect",
    "compare",
    "continual",
    "efficiency",
    "evaluate",
    "features",
    "load_policy",
    "online",
    "pull",
    "push",
    "report",
    "study_report",
    "study_run",
    "study_status",
    "train",
    "transfer_report",
    "transfer_run",
)


_, __getattr__, __dir__ = lazy_exports(  # loaded on first use (PEP 562)
    __name__, {"api": _API, "version": ("__version__", "code_version")}, globals()
)
