"""Skill Builder's curriculum: transfer advantages between tasks, and the cheapest order to learn them.

A core package like the five folders' public surfaces, but for one job: the maths on a measured
transfer-advantage matrix.  It imports none of the five folders (only ``nsl.errors`` and
``nsl.workspace``); ``nsl.study.transfer`` measures the matrix and the CLI wires both.

    TransferMatrix, load_matrix, save_matrix, matrix_from_dict, advantage, SCRATCH, t_interval   # matrix.py
    build_curriculum, Curriculum, Tree, edge_cost                                    # tree.py
    plot_curriculum                                                                  # plot.py
    rank_correlation, Correlation, Candidate, rank_candidates                        # rank.py

Definitions (AUC, advantage, cost, arborescence, proxy) are in the module docstrings and in
``docs/transfer.md``.
"""

from .matrix import (
    SCRATCH,
    Advantage,
    TransferMatrix,
    advantage,
    load_matrix,
    matrix_from_dict,
    save_matrix,
    t_interval,
)
from .plot import plot_curriculum
from .rank import Candidate, Correlation, rank_candidates, rank_correlation
from .tree import Curriculum, Tree, build_curriculum, edge_cost

__all__ = [
    "SCRATCH",
    "Advantage",
    "Candidate",
    "Correlation",
    "Curriculum",
    "TransferMatrix",
    "Tree",
    "advantage",
    "build_curriculum",
    "edge_cost",
    "load_matrix",
    "matrix_from_dict",
    "plot_curriculum",
    "rank_candidates",
    "rank_correlation",
    "save_matrix",
    "t_interval",
]
