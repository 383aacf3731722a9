"""The named scene seeds: which scenes choose a recipe and which report it.

Episode ``i`` of an evaluation with seed ``S`` is scene ``(S, i)`` on every
shift and for every policy, so two evaluations with the same seed are paired.
The project keeps three disjoint sets apart (the research practice in
``docs/experiments/README.md``):

* :data:`SELECTION_SCENES` score every choice: recipes, steps, early stopping.
* :data:`REPORTING_SCENES` report a frozen recipe (the study's tables).
* :data:`FINAL_REPORTING_SCENES` were drawn at random once the fine-tuning
  recipe was frozen (``10_000 + secrets.randbelow(90_000)``), for the committed
  tables; nothing is ever chosen on them, and no recipe or severity changes
  after a table is measured on them.

:data:`EVAL_SCENES` is what ``nsl eval`` uses when not told otherwise.
"""

from __future__ import annotations

EVAL_SCENES = 1000
REPORTING_SCENES = 2000
SELECTION_SCENES = 3000
FINAL_REPORTING_SCENES = 51425

__all__ = ["EVAL_SCENES", "FINAL_REPORTING_SCENES", "REPORTING_SCENES", "SELECTION_SCENES"]
