"""``nsl report RUN``: Markdown plus PNG figures from the evaluation records in a run folder.

:func:`write_report` looks under ``RUN`` (any depth, skipping its own output
folder) for the records of :mod:`nsl.eval.records`:

* every ``curve.csv`` (or a trainer's ``eval.jsonl`` with curve fields, when
  its folder has no curve.csv): a Fig. 5.7-style curve and the table of steps
  chosen by each early-stopping criterion;
* every ``matrix.json``: a heatmap, the Table 5.3-shaped table and the
  continual-learning metrics;
* every ``tiers.json``: a Fig. 5.6-style sample-efficiency plot and the
  Table 5.2-shaped table.

It writes ``RUN/report/report.md``, ``report.json`` (the numbers) and the
PNGs next to them, each through a temporary file and a rename.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from nsl.errors import UnknownReferenceError
from nsl.workspace import atomic_write_bytes, atomic_write_json

from .continual import ContinualMetrics, continual_metrics
from .early_stopping import choices_table, choose_steps, load_early_stop
from .plots import plot_curve, plot_matrix, plot_tiers
from .records import (
    CURVE_FILE,
    EARLY_STOP_FILE,
    MATRIX_FILE,
    REPORT_DIR,
    TIERS_FILE,
    PerformanceMatrix,
    TierResults,
    read_curve,
    read_eval_jsonl,
)

EVAL_JSONL = "eval.jsonl"  # what the trainer writes for every eval_fn call
REPORT_FILE = "report.md"
REPORT_JSON = "report.json"


@dataclass
class ReportResult:
    markdown: Path
    json: Path
    figures: list[Path] = field(default_factory=list)
    sections: list[str] = field(default_factory=list)  # the record files that made it in, relative to RUN


def pipe_table(head: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown table: the header row, its rule, then one line per row of cells."""
    return "\n".join(
        ["| " + " | ".join(head) + " |", "|" + "---|" * len(head), *("| " + " | ".join(r) + " |" for r in rows)]
    )


def tiers_table(tiers: TierResults, intervals: bool = True) -> str:
    """Table 5.2's shape: base policy, each tier, the best tier (change vs base), comparison methods."""
    ks, comps = tiers.tiers, tiers.comparison_names
    rows = []
    for name, row in tiers.rows.items():
        cells = [name.replace("_", " "), "-" if row.base is None else row.base.percent(intervals)]
        measured = {k: v for k, v in (row.tiers or {}).items() if v is not None}
        cells += ["-" if k not in measured else measured[k].percent(intervals) for k in ks]
        if measured:
            k_best = max(measured, key=lambda k: (measured[k].success_rate, -k))
            best = measured[k_best].success_rate
            change = "" if row.base is None else f" ({100 * (best - row.base.success_rate):+.0f})"
            cells.append(f"{100 * best:.0f}%{change} @{k_best}")
        else:
            cells.append("-")
        comparisons = row.comparisons or {}
        cells += ["-" if comparisons.get(c) is None else comparisons[c].percent(intervals) for c in comps]
        rows.append(cells)
    return pipe_table(["challenge", "base", *[str(k) for k in ks], "best (change)", *comps], rows)


def matrix_table(matrix: PerformanceMatrix, intervals: bool = True, pretty: bool = False) -> str:
    """The raw matrix: one row per stage, one column per task (``pretty``: underscores in their names as spaces)."""

    def name(s: str) -> str:
        return s.replace("_", " ") if pretty else s

    rows = []
    for i, stage in enumerate(matrix.stages):
        rates = [matrix.rate(i, j) for j in range(len(matrix.tasks))]
        rows.append([f"{i}: {name(stage)}", *["-" if r is None else r.percent(intervals) for r in rates]])
    return pipe_table(["after stage", *map(name, matrix.tasks)], rows)


def _find(run: Path, name: str) -> list[Path]:
    skip = run / REPORT_DIR
    return sorted(p for p in run.rglob(name) if skip not in p.parents)


def _slug(run: Path, folder: Path, stem: str) -> str:
    rel = folder.relative_to(run).as_posix()
    return stem if rel == "." else f"{stem}-{rel.replace('/', '-')}"


def write_report(
    run: str | Path, out_dir: str | Path | None = None, title: str | None = None, intervals: bool = True
) -> ReportResult:
    """Write ``report.md``, ``report.json`` and PNG figures for the records found under ``run``."""
    from nsl import code_version

    run = Path(run)
    if not run.is_dir():
        raise UnknownReferenceError(f"run folder {str(run)!r} does not exist; pass the folder a run wrote")
    out = Path(out_dir) if out_dir is not None else run / REPORT_DIR
    curves = [(p.parent, read_curve(p), p) for p in _find(run, CURVE_FILE)]
    with_csv = {folder for folder, _, _ in curves}
    for p in _find(run, EVAL_JSONL):
        if p.parent not in with_csv:
            rows = read_eval_jsonl(p)
            if rows:
                curves.append((p.parent, rows, p))
    matrices = [(p, PerformanceMatrix.load(p)) for p in _find(run, MATRIX_FILE)]
    tier_sets = [(p, TierResults.load(p)) for p in _find(run, TIERS_FILE)]
    if not (curves or matrices or tier_sets):
        raise UnknownReferenceError(
            f"{run} holds no {CURVE_FILE}, {EVAL_JSONL}, {MATRIX_FILE} or {TIERS_FILE}; "
            "point nsl report at a training, continual or tiers run folder"
        )

    md = [
        f"# {title or f'Report: {run.name}'}",
        "",
        f"Generated by nsl {code_version()} from `{run}`. Success rates are percentages with 95% Wilson "
        "intervals in brackets; changes are in percentage points.",
        "",
    ]
    numbers: dict = {"run": str(run), "code_version": code_version(), "curves": {}, "continual": {}, "tiers": {}}
    result = ReportResult(out / REPORT_FILE, out / REPORT_JSON)

    for folder, rows, path in sorted(curves, key=lambda c: str(c[2])):
        if not rows:
            continue
        info = load_early_stop(folder / EARLY_STOP_FILE)
        cfg = info.get("config") or {}
        choices = choose_steps(rows, cfg.get("patience"), cfg.get("min_delta", 0.0))
        rel = path.relative_to(run).as_posix()
        png = plot_curve(
            rows,
            out / f"{_slug(run, folder, 'curve')}.png",
            choices,
            title=f"Offline fine-tuning: {folder.relative_to(run).as_posix()}"
            if folder != run
            else "Offline fine-tuning",
            references=info.get("references"),
        )
        result.figures.append(png)
        result.sections.append(rel)
        md += [
            f"## Early stopping: `{rel}`",
            "",
            f"![learning curve]({png.name})",
            "",
            "The step each criterion chooses"
            + (f" (patience {cfg['patience']} evaluations)" if cfg.get("patience") else " (best of the whole curve)")
            + ", the evaluated success there, and its distance from the step with the highest evaluated "
            "target success. The chosen step's success is measured on the same episodes that chose it; "
            "re-evaluate it with another `--seed` for an unbiased number.",
            "",
            choices_table(choices),
            "",
        ]
        numbers["curves"][rel] = {
            "choices": {k: v.to_dict() for k, v in choices.items()},
            "early_stop": info or None,
            "evaluations": len(rows),
        }

    for path, matrix in matrices:
        metrics: ContinualMetrics = continual_metrics(matrix)
        rel = path.relative_to(run).as_posix()
        png = plot_matrix(matrix, out / f"{_slug(run, path.parent, 'matrix')}.png")
        result.figures.append(png)
        result.sections.append(rel)
        md += [
            f"## Continual learning: `{rel}`",
            "",
            f"![performance matrix]({png.name})",
            "",
            "In the shape of the study's Table 5.3: *continual* is each task's success right after its own "
            "stage; *vs base* and *vs single* compare it with the initial policy and with single-step "
            "fine-tuning from the initial checkpoint; *forgetting* is the best success since the task's "
            "stage minus the final one.",
            "",
            metrics.markdown(intervals),
            "",
            "Success after every stage:",
            "",
            matrix_table(matrix, intervals),
            "",
        ]
        numbers["continual"][rel] = metrics.to_dict()

    for path, tiers in tier_sets:
        rel = path.relative_to(run).as_posix()
        png = plot_tiers(tiers, out / f"{_slug(run, path.parent, 'tiers')}.png")
        result.figures.append(png)
        result.sections.append(rel)
        md += [
            f"## Sample efficiency: `{rel}`",
            "",
            f"![sample efficiency]({png.name})",
            "",
            "In the shape of the study's Table 5.2: success of the fine-tuned policy by number of target "
            "attempts in the dataset.",
            "",
            tiers_table(tiers, intervals),
            "",
        ]
        numbers["tiers"][rel] = tiers.to_dict()

    atomic_write_json(result.json, numbers)
    atomic_write_bytes(result.markdown, "\n".join(md).encode())
    return result
