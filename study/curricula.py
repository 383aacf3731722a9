"""Run the optimal and pessimal curricula of a measured transfer as real training sequences (Skill Builder's check).

``nsl transfer run`` measures every ``A(src -> dst)`` from each source task's *catalogued* checkpoint; a curriculum
adds them up to predict what learning all tasks in its order costs.  Two assumptions sit in that sum, and this
module measures both, with training seeds the matrix did not use (by default the plan's seeds shifted past its
highest), so that the measurement is a replication and not the same runs again:

* **The prediction.**  Each tree is followed for real.  A task whose parent is ``scratch`` is taken as learned:
  the curriculum continues from its catalogued checkpoint, as the matrix does (its edge has ``A = 1`` by
  definition).  Every other task is fine-tuned, with the transfer's steps, data mix and learning rate, from the
  checkpoint that *this curriculum* produced for its parent, or from the parent's catalogued checkpoint when the
  parent hangs from scratch.  Its measured advantage is ``AUC(that run) / AUC(scratch run, same seed)``, and the
  tree's measured cost ``-sum(A)``, next to the predicted one.
* **Conditional independence.**  The source assumed that a task's transfer cost does not depend on how its
  source was reached.  For every edge ``p -> t`` whose ``p`` was itself reached by fine-tuning in the curriculum
  (depth 2 or more below scratch), the same fine-tune is also run from ``p``'s catalogued checkpoint, with the
  same seed: the paired difference of the two advantages is the test.

Units (``X`` is the transfer's name; the tags are the transfer's own where a run is the same)::

    train:scratch-DST-nK-kS-sSEED              the denominators, for the new seeds
    train:ft-P-to-T-nK-kS-sSEED                from P's catalogued checkpoint (a scratch child, or the control)
    train:ft-via-I-..-J-to-T-nK-kS-sSEED       from the checkpoint the curriculum made for P along the path of
                                               tasks I -> .. -> J = P (their places in the plan's task list)

Files in ``$NSL_HOME/transfers/X/curricula/``: ``plan.json`` (the trees and seeds), ``units.json``,
``status.json``, ``curricula.json`` and ``curricula.md``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from nsl import code_version, workspace
from nsl.errors import ConfigError
from nsl.refs import check_name

from .transfer import TransferPlan, build_transfer_units, ft_tag, scratch_tag
from .units import Unit, slug

FOLDER = "curricula"
RESULT_JSON = "curricula.json"
RESULT_MD = "curricula.md"
TREES = ("optimal", "pessimal")


@dataclass(frozen=True)
class CurriculaPlan:
    """What ``nsl transfer curricula`` runs: the two trees (each task's parent) and the training seeds."""

    transfer: str
    seeds: tuple[int, ...]
    trees: dict[str, dict[str, str]]  # tree name -> {task: parent}
    source: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("source")
        return d


def default_seeds(plan: TransferPlan) -> tuple[int, ...]:
    """As many seeds as the matrix used, none of them the matrix's own."""
    top = max(plan.seeds)
    return tuple(top + 1 + i for i in range(len(plan.seeds)))


def path_to(parent: dict[str, str], task: str) -> list[str]:
    """The tasks from the scratch child down to ``task`` (``[root, ..., task]``)."""
    from nsl.curriculum import SCRATCH

    out = [task]
    while parent[out[-1]] != SCRATCH:
        out.append(parent[out[-1]])
        if len(out) > len(parent):
            raise ConfigError(f"curriculum tree {parent} has a cycle; it is not a tree rooted at scratch")
    return out[::-1]


def edge_tag(plan: TransferPlan, path: list[str], seed: int) -> str:
    """The train tag of the last edge of ``path`` (``path[-2] -> path[-1]``) as the curriculum runs it."""
    if len(path) == 2:
        return ft_tag(plan, path[0], path[1], seed)
    dst = path[-1]
    via = "-".join(str(plan.task_names.index(t)) for t in path[:-1])  # tasks by their place in the plan: short
    return f"ft-via-{via}-to-{slug(dst)}-n{plan.task(dst).episodes}-k{plan.steps}-s{seed}"


def build_curricula_units(
    plan: TransferPlan, cplan: CurriculaPlan, base_ref: str, base, ft_lr: float
) -> dict[str, Unit]:
    """Every unit that following the trees (and their controls) needs, by name."""
    from nsl.curriculum import SCRATCH

    shifted = TransferPlan(**{**{k: getattr(plan, k) for k in plan.__dataclass_fields__}, "seeds": cplan.seeds})
    pool = build_transfer_units(shifted, base_ref, base, ft_lr)  # scratch and direct fine-tunes, new seeds
    units: dict[str, Unit] = {}

    def need(name: str) -> None:
        for d in pool[name].deps:
            if d not in units:
                units[d] = pool[d]
        units[name] = pool[name]

    for seed in cplan.seeds:
        for t in plan.task_names:
            need(f"train:{scratch_tag(plan, t, seed)}")
        for parent in cplan.trees.values():
            for t, p in parent.items():
                if p == SCRATCH:
                    continue
                path = path_to(parent, t)
                if len(path) == 2:
                    need(f"train:{ft_tag(plan, p, t, seed)}")
                    continue
                need(f"train:{ft_tag(plan, p, t, seed)}")  # the control: p's catalogued checkpoint
                tag, into = edge_tag(plan, path, seed), edge_tag(plan, path[:-1], seed)
                direct = pool[f"train:{ft_tag(plan, p, t, seed)}"]
                params = {
                    **direct.params,
                    "checkpoint": check_name("checkpoint", f"{plan.name}-{tag}"),
                    "init_ref": f"ckpt:{plan.name}-{into}@latest",
                }
                units[f"train:{tag}"] = Unit(f"train:{tag}", "train", params, (*direct.deps, f"train:{into}"))
    return units


# --- measurement ----------------------------------------------------------------------------------------------------


def _mean_t(values: list[float]) -> tuple[float | None, tuple[float, float] | None]:
    """The mean and its 95% Student-t interval (None, None for no values)."""
    from nsl.curriculum import t_interval

    return (sum(values) / len(values), t_interval(values)) if values else (None, None)


def measure(plan: TransferPlan, cplan: CurriculaPlan, matrix, auc, last) -> dict[str, Any]:
    """Predicted against measured cost of each tree, and the conditional-independence pairs.

    ``auc(tag)`` / ``last(tag)``: a finished run's AUC and final success on its target (None while unfinished);
    ``matrix``: the transfer's :class:`~nsl.curriculum.TransferMatrix` (the predictions)."""
    from nsl.curriculum import SCRATCH, Tree, build_curriculum

    floor = plan.floor
    reference = build_curriculum(matrix)

    def ratio(tag: str, dst: str, seed: int) -> float | None:
        a, sc = auc(tag), auc(scratch_tag(plan, dst, seed))
        return None if a is None or sc is None else a / max(sc, floor)

    out: dict[str, Any] = {
        "seeds": list(cplan.seeds),
        "auc_floor": floor,
        "trees": {},
        "independence": [],
        "code_version": code_version(),
        "reference": {"from_base": reference.from_base, "from_scratch": reference.from_scratch},
    }
    for name, parent in cplan.trees.items():
        edges, cost = [], {s: 0.0 for s in cplan.seeds}
        for t in Tree(parent, {}, 0.0).order(plan.task_names):
            p = parent[t]
            row: dict[str, Any] = {"from": p, "to": t, "predicted": matrix.get(p, t)}
            if p == SCRATCH:  # taken as learned; its success is what the scratch runs reach with the same steps
                finals = [v for s in cplan.seeds if (v := last(scratch_tag(plan, t, s))) is not None]
                row.update(
                    measured=1.0,
                    interval=None,
                    per_seed={str(s): 1.0 for s in cplan.seeds},
                    final=sum(finals) / len(finals) if finals else None,
                )
                for s in cplan.seeds:
                    cost[s] -= 1.0
            else:
                path = path_to(parent, t)
                ratios = {s: r for s in cplan.seeds if (r := ratio(edge_tag(plan, path, s), t, s)) is not None}
                finals = [v for s in cplan.seeds if (v := last(edge_tag(plan, path, s))) is not None]
                for s in cplan.seeds:
                    cost[s] = cost[s] - ratios[s] if s in ratios and cost[s] is not None else None
                mean, ci = _mean_t(list(ratios.values()))
                row.update(
                    measured=mean,
                    interval=ci,
                    per_seed={str(s): v for s, v in ratios.items()},
                    final=sum(finals) / len(finals) if finals else None,
                    path=path,
                )
                if len(path) > 2:
                    diffs = {s: ratios[s] - d for s in ratios if (d := ratio(ft_tag(plan, p, t, s), t, s)) is not None}
                    auc_diffs = [
                        a - d
                        for s in cplan.seeds
                        if (a := auc(edge_tag(plan, path, s))) is not None
                        and (d := auc(ft_tag(plan, p, t, s))) is not None
                    ]
                    mean_d, ci_d = _mean_t(list(diffs.values()))
                    mean_a, ci_a = _mean_t(auc_diffs)
                    out["independence"].append(
                        {
                            "tree": name,
                            "path": path,
                            "matrix": matrix.get(p, t),
                            "difference": mean_d,
                            "interval": ci_d,
                            "per_seed": {str(s): d for s, d in diffs.items()},
                            "auc_difference": mean_a,
                            "auc_interval": ci_a,
                        }
                    )
            edges.append(row)
        complete = all(c is not None for c in cost.values())
        mean, ci = _mean_t(list(cost.values()) if complete else [])
        finals = [e["final"] for e in edges]
        out["trees"][name] = {
            "predicted": sum(-e["predicted"] for e in edges),
            "measured": mean,
            "interval": ci,
            "mean_final": None if None in finals else sum(finals) / len(finals),
            "per_seed": {str(s): c for s, c in cost.items()} if complete else {},
            "edges": edges,
            "complete": complete,
        }
    return out


def render(result: dict[str, Any], transfer: str) -> str:
    """curricula.md: each tree's edges (predicted and measured A) and costs, then the independence check."""

    def num(v, signed=False):
        return "n/a" if v is None else f"{v:+.2f}" if signed else f"{v:.2f}"

    def ci(c):
        return "" if not c else f" [{c[0]:.2f}, {c[1]:.2f}]"

    lines = [
        f"# Curricula of transfer {transfer}, followed for real",
        "",
        f"Training seeds {result['seeds']} (the matrix used others). A task learned from scratch is taken as "
        "learned (its catalogued checkpoint; A = 1 by definition); every other task is fine-tuned from the "
        "checkpoint the curriculum made for its parent. Measured A = AUC(that run) / AUC(scratch, same seed), "
        f"scratch AUCs floored at {result['auc_floor']:.3f}; intervals are 95% Student-t over seeds. "
        "Definitions: docs/transfer.md.",
        "",
    ]
    for name, tree in result["trees"].items():
        lines += [
            f"## {name.capitalize()} curriculum",
            "",
            "| task | learned from | A predicted | A measured | success at the last step |",
            "|---|---|---|---|---|",
        ]
        for e in tree["edges"]:
            final = num(e["final"]) + (" (the scratch runs; taken as learned)" if e["from"] == "scratch" else "")
            lines.append(
                f"| {e['to']} | {e['from']} | {num(e['predicted'])} | {num(e['measured'])}"
                f"{ci(e['interval'])} | {final} |"
            )
        lines += [
            "",
            f"Cost (C = -sum A; lower is better): predicted **{tree['predicted']:+.2f}**, measured "
            f"**{num(tree['measured'], True)}**{ci(tree['interval'])}"
            + ("" if tree["complete"] else " (not every run has finished)")
            + f". Mean success at the last step over the tasks: {num(tree['mean_final'])}.",
            "",
        ]
    ref = result["reference"]
    lines += [
        f"Predicted reference costs: every task from the base {num(ref['from_base'], True)}, every task from "
        f"scratch {num(ref['from_scratch'], True)}.",
        "",
        "## Does a task's transfer depend on how its source was reached?",
        "",
    ]
    if not result["independence"]:
        lines.append(
            "Neither tree has an edge whose source was itself reached by fine-tuning in the curriculum, so "
            "there is nothing to compare: every fine-tune starts from a catalogued checkpoint."
        )
    else:
        lines += [
            "Each row fine-tunes the path's last task from two checkpoints of its source: the one the "
            "curriculum made along the path, and the catalogued one, with the same seeds. Difference = "
            "A(from the path's checkpoint) - A(from the catalogued one), and the same for the AUC itself "
            "(mean success over the run, in points).",
            "",
            "| tree | path | A in the matrix | difference of A | difference of AUC, points |",
            "|---|---|---|---|---|",
        ]
        for r in result["independence"]:
            auc_d = "n/a" if r["auc_difference"] is None else f"{100 * r['auc_difference']:+.1f}"
            auc_ci = (
                ""
                if not r["auc_interval"]
                else (f" [{100 * r['auc_interval'][0]:+.1f}, {100 * r['auc_interval'][1]:+.1f}]")
            )
            lines.append(
                f"| {r['tree']} | {' -> '.join(r['path'])} | {num(r['matrix'])} | "
                f"{num(r['difference'], True)}{ci(r['interval'])} | {auc_d}{auc_ci} |"
            )
    return "\n".join(lines)


def folder(transfer: str) -> Path:
    return workspace.home() / "transfers" / transfer / FOLDER
