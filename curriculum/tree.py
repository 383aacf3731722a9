"""The curriculum: which task to learn from which, as a minimum spanning arborescence of the cost graph.

The cost graph has one vertex per task plus ``scratch``.  An edge ``src -> dst`` costs ``C = -A(src -> dst)``
(the source's choice): the edges ``scratch -> dst`` cost ``-1``.  ``-A`` rather than ``1/A`` because a
fine-tune that learns nothing has ``A = 0`` (``1/A`` would be infinite), and because summing ``-A`` ranks
trees by their total advantage, which is what the source compared.  A curriculum learns each task once,
from scratch or from one task learned before it: a spanning arborescence rooted at ``scratch`` (every task
has exactly one parent, and following parents always ends at scratch).  Its predicted cost is the sum of
its edges' costs.

* optimal   the minimum spanning arborescence (Chu-Liu/Edmonds, ``networkx``): the most total advantage;
* pessimal  the maximum one: the least total advantage (the source's contrast);
* from base every task but the base learned from the base, the base from scratch (when the base is a task);
* from scratch every task from scratch: ``-n``.

The source used Kruskal's algorithm on the directed graph, which can return a set of edges that is not a
curriculum (a task with two parents, or none reachable from scratch); Edmonds' algorithm is exact.

Ties: advantages are compared to 6 decimal places.  Among trees of equal cost, the one chosen has the
edges that come first in this order: edges from scratch, then edges from tasks in the matrix's task order,
each by destination in task order (so a tie between scratch and a task is resolved as "from scratch").
This is exact: each edge weight is ``round(C * 1e6) * M + rank`` in integers, with ``M`` larger than any
sum of ranks, so ranks only decide between trees of equal rounded cost.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import networkx as nx

from nsl.errors import ConfigError, UnknownReferenceError

from .matrix import SCRATCH, TransferMatrix

SCALE = 10**6  # advantages compared to 6 decimal places


def edge_cost(advantage: float) -> float:
    """The cost of an edge with transfer advantage ``advantage`` (``C = -A``; lower is better)."""
    return -float(advantage)


@dataclass(frozen=True)
class Tree:
    """A curriculum: each task's parent (``scratch`` or a task) and the predicted cost."""

    parent: Mapping[str, str]
    advantage: Mapping[str, float]  # A(parent -> task) of each task's edge
    cost: float  # sum of edge costs

    def order(self, tasks: Sequence[str]) -> list[str]:
        """A learning order: breadth first from scratch, children in ``tasks`` order."""
        children: dict[str, list[str]] = {}
        for t in tasks:
            children.setdefault(self.parent[t], []).append(t)
        out, frontier = [], [SCRATCH]
        while frontier:
            nxt = []
            for v in frontier:
                out += children.get(v, [])
                nxt += children.get(v, [])
            frontier = nxt
        return out

    def edges(self, tasks: Sequence[str]) -> list[tuple[str, str, float]]:
        """(parent, task, A) in learning order."""
        return [(self.parent[t], t, self.advantage[t]) for t in self.order(tasks)]

    def to_dict(self, tasks: Sequence[str]) -> dict[str, Any]:
        return {
            "cost": self.cost,
            "order": self.order(tasks),
            "edges": [{"from": s, "to": d, "advantage": a, "cost": edge_cost(a)} for s, d, a in self.edges(tasks)],
        }


@dataclass(frozen=True)
class Curriculum:
    tasks: tuple[str, ...]
    optimal: Tree
    pessimal: Tree
    from_base: float | None  # predicted cost of learning every task from the base (None: no base among the tasks)
    from_scratch: float
    base: str | None

    def to_dict(self) -> dict[str, Any]:
        return {
            "tasks": list(self.tasks),
            "base": self.base,
            "cost_definition": "C = -A(src -> dst); scratch edges -1",
            "optimal": self.optimal.to_dict(self.tasks),
            "pessimal": self.pessimal.to_dict(self.tasks),
            "from_base": self.from_base,
            "from_scratch": self.from_scratch,
        }

    def lines(self) -> list[str]:
        """The two trees and the four predicted costs, for a terminal."""
        out = []
        for label, tree in (("optimal", self.optimal), ("pessimal", self.pessimal)):
            out.append(f"{label} curriculum (predicted cost {tree.cost:+.2f}):")
            out += [f"  {t:<28} from {s:<28} A = {a:.2f}" for s, t, a in tree.edges(self.tasks)]
        out.append("predicted cost (C = -A; lower is better):")
        rows = [("optimal", self.optimal.cost), ("pessimal", self.pessimal.cost)]
        rows.append((f"all from the base ({self.base})" if self.base else "all from the base", self.from_base))
        rows.append(("all from scratch", self.from_scratch))
        out += [f"  {k:<32} {'n/a (no base task)' if v is None else f'{v:+.2f}'}" for k, v in rows]
        return out


def _check_tasks(matrix: TransferMatrix, tasks: Sequence[str] | None) -> tuple[str, ...]:
    tasks = tuple(matrix.tasks if not tasks else tasks)
    for t in tasks:
        if t not in matrix.tasks:
            raise UnknownReferenceError(
                f"task {t!r} is not in the transfer matrix; its tasks: {', '.join(matrix.tasks)}"
            )
    if len(set(tasks)) != len(tasks):
        raise ConfigError(f"tasks {list(tasks)} repeat a task; name each once")
    order = {t: i for i, t in enumerate(matrix.tasks)}
    tasks = tuple(sorted(tasks, key=order.__getitem__))
    for s in tasks:
        for d in tasks:
            if s != d and matrix.get(s, d) is None:
                raise ConfigError(
                    f"transfer matrix has no measurement of A({s} -> {d}); finish `nsl transfer run` "
                    "or leave one of the two tasks out"
                )
    return tasks


def _tree(matrix: TransferMatrix, tasks: tuple[str, ...], sign: int) -> Tree:
    """The minimum spanning arborescence of the cost graph under ``sign * C`` (1: optimal, -1: pessimal)."""
    sources = [SCRATCH, *tasks]
    edges = [(s, d) for s in sources for d in tasks if s != d]
    mult = len(tasks) * len(edges) + 1  # larger than any sum of ranks over a tree's edges
    g = nx.DiGraph()
    g.add_nodes_from(sources)
    for rank, (s, d) in enumerate(edges):
        g.add_edge(s, d, weight=round(sign * edge_cost(matrix.get(s, d)) * SCALE) * mult + rank)
    arb = nx.minimum_spanning_arborescence(g, attr="weight", preserve_attrs=False)
    parent = {d: s for s, d in arb.edges()}
    if set(parent) != set(tasks) or next(iter(nx.topological_sort(arb))) != SCRATCH:
        raise ConfigError("no spanning arborescence rooted at scratch was found; this is a bug, please report it")
    adv = {t: float(matrix.get(parent[t], t)) for t in tasks}
    return Tree(parent, adv, sum(edge_cost(a) for a in adv.values()))


def build_curriculum(matrix: TransferMatrix, tasks: Sequence[str] | None = None) -> Curriculum:
    """The optimal and pessimal curricula over ``tasks`` (default: all of the matrix's), and reference costs."""
    tasks = _check_tasks(matrix, tasks)
    base = matrix.base if matrix.base in tasks else None
    from_base = None
    if base is not None:
        from_base = edge_cost(1.0) + sum(edge_cost(matrix.get(base, t)) for t in tasks if t != base)
    return Curriculum(
        tasks, _tree(matrix, tasks, 1), _tree(matrix, tasks, -1), from_base, len(tasks) * edge_cost(1.0), base
    )
