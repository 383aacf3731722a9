"""The model card: a checkpoint's catalog entry as a Hugging Face model card (pure text, no database).

The model card (``README.md`` in every checkpoint folder) follows Hugging
Face conventions (YAML front matter with ``library_name``, ``tags``,
``pipeline_tag`` and a ``model-index`` of evaluation results), so a
checkpoint folder can be pushed as a model repository as it is.  Its body
says what the model is for (task and shift), what it saw (datasets, versions,
tiers, batch weights), how it did (evaluations pooled per shift and split)
and where it came from (lineage).  The lineage trees of ``nsl catalog
lineage`` are in :mod:`.lineage`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from nsl.checkpoint_format import CONFIG_FILE, WEIGHTS_FILE
from nsl.stats import wilson_interval

from .records import CheckpointEntry, DatasetEntry, DataUse, EvaluationEntry, short_hash

LIBRARY_NAME = "nsl"
BASE_TAGS = ("nsl", "robotics", "grasping", "reinforcement-learning", "qt-opt", "offline-rl", "continual-learning")


def pooled_results(evaluations: Sequence[EvaluationEntry]) -> list[dict[str, Any]]:
    """Evaluations summed per (shift, split), with a Wilson interval on the pooled counts."""
    pooled: dict[tuple[str, str], list[int]] = {}
    for e in evaluations:
        acc = pooled.setdefault((e.shift, e.split), [0, 0, 0])
        acc[0] += e.successes
        acc[1] += e.episodes
        acc[2] += 1
    rows = []
    for (shift, split), (s, n, runs) in sorted(pooled.items()):
        lo, hi = wilson_interval(s, n)
        rows.append(
            {
                "shift": shift,
                "split": split,
                "successes": s,
                "episodes": n,
                "runs": runs,
                "rate": s / n,
                "ci_low": lo,
                "ci_high": hi,
            }
        )
    return rows


def _front_matter(entry: CheckpointEntry, results: list[dict[str, Any]], tags: Sequence[str], license_id: str) -> str:
    from huggingface_hub import EvalResult, ModelCardData

    eval_results = [
        EvalResult(
            task_type="robotics",
            task_name="vision-based grasping",
            dataset_type="nsl-shift",
            dataset_name=f"{r['shift']} ({r['split']} objects)",
            dataset_config=r["shift"],
            dataset_split=r["split"],
            metric_type="success_rate",
            metric_name="grasp success rate",
            metric_value=round(r["rate"], 4),
        )
        for r in results
    ]
    data = ModelCardData(
        library_name=LIBRARY_NAME,
        license=license_id,
        pipeline_tag="robotics",
        tags=list(tags),
        model_name=entry.ref,
        eval_results=eval_results or None,
        nsl={
            "checkpoint_id": entry.id,
            "name": entry.name,
            "step": entry.step,
            "parent": entry.parent,
            "shift": entry.shift,
            "code_version": entry.code_version,
            "data": [
                {"dataset": u.dataset, "version": u.version, "tier": u.tier, "weight": u.weight, "hash": u.hash}
                for u in entry.data
            ],
        },
    )
    return f"---\n{data.to_yaml()}\n---\n"


def _pct(x: float) -> str:
    return f"{100 * x:.1f}%"


def render_model_card(
    entry: CheckpointEntry,
    ancestors: Sequence[CheckpointEntry],
    datasets: Mapping[tuple[str, int], DatasetEntry],
    evaluations: Sequence[EvaluationEntry],
    info: Mapping[str, Any] | None = None,
) -> str:
    """The model card text.

    ``ancestors`` is the parent chain (parent first); ``datasets`` maps
    (name, version) to the rows of the datasets ``entry`` used.  ``info`` may
    hold ``summary`` (a paragraph), ``tags`` (extra tags), ``license`` and
    ``published``: the published lineage (``nsl.catalog.published_lineage``),
    which then gives the data and ancestors, including those known only from
    a pull.
    """
    info = dict(info or {})
    published = list(info.get("published") or [])
    results = pooled_results(evaluations)
    tags = list(dict.fromkeys([*BASE_TAGS, *info.get("tags", ()), entry.shift]))
    out = [_front_matter(entry, results, tags, str(info.get("license", "apache-2.0")))]
    out.append(f"# {entry.name} @ step {entry.step}\n")
    origin = (
        f"fine-tuned from `{ancestors[0].ref}` (`{ancestors[0].short_id}`)"
        if ancestors
        else f"fine-tuned from `{published[1]['name']}@{published[1]['step']}` (`{published[1]['id'][:12]}`)"
        if len(published) > 1
        else f"fine-tuned from a removed checkpoint `{entry.parent[:12]}`"
        if entry.parent
        else "trained from scratch"
    )
    out.append(
        "A QT-Opt grasping Q-function for simulated vision-based bin grasping (MuJoCo, RGB camera), "
        f'made with nsl ("never stop learning"). It was trained for the shift **{entry.shift}** and '
        f"{origin}.\n"
    )
    if info.get("summary"):
        out.append(str(info["summary"]).strip() + "\n")
    out.append(
        f"- checkpoint id: `{entry.id}` (sha256 of `{WEIGHTS_FILE}` and the canonical `{CONFIG_FILE}`)\n"
        f"- gradient step: {entry.step}\n- code version: `{entry.code_version}`\n- created: {entry.created}\n"
    )

    out.append("## Training data\n")
    if published and published[0].get("data"):
        out.append("| dataset | shift | episodes | tier | batch weight | content hash |\n|---|---|---|---|---|---|")
        for d in published[0]["data"]:
            out.append(
                f"| `{d['dataset']}@v{d['version']}` | {d.get('shift', '?')} | {d.get('episodes', '?')} | "
                f"{d.get('tier') or 'all'} | {d['weight']:g} | `{d.get('hash') or '?'}` |"
            )
        out.append("")
    elif entry.data:
        out.append("| dataset | shift | episodes | tier | batch weight | content hash |\n|---|---|---|---|---|---|")
        for u in entry.data:
            d = datasets.get((u.dataset, u.version))
            shift = d.shift_name if d else "?"
            episodes = str(d.episodes) if d else "?"
            out.append(
                f"| `{u.dataset}@v{u.version}` | {shift} | {episodes} | {u.tier or 'all'} | "
                f"{u.weight:g} | `{short_hash(u.hash)}` |"
            )
        out.append("")
    else:
        out.append("No datasets were recorded for this checkpoint.\n")

    out.append("## Lineage\n")
    out.append("Newest first; each checkpoint started from the weights of the one below it.\n")
    if published:
        for n in published:
            uses = ", ".join(
                f"{d['dataset']}@v{d['version']}{':' + str(d['tier']) if d.get('tier') else ''} x{d['weight']:g}"
                for d in n.get("data", [])
            )
            out.append(
                f"- `{n['name']}@{n['step']}` (`{str(n['id'])[:12]}`), shift {n['shift']}; data: {uses or 'none'}"
            )
        if published[-1].get("parent"):
            out.append(f"- `{str(published[-1]['parent'])[:12]}` (not published)")
    else:
        for c in [entry, *ancestors]:
            uses = DataUse.mix(c.data)
            out.append(f"- `{c.ref}` (`{c.short_id}`), shift {c.shift}; data: {uses or 'none'}")
        last = ancestors[-1] if ancestors else entry
        if last.parent:
            out.append(f"- `{last.parent[:12]}` (removed from the catalog)")
    out.append("")

    out.append("## Evaluation\n")
    if not results and published and published[0].get("evaluations"):
        results = published[0]["evaluations"]
        out.append("Not evaluated in this workspace yet; these are the evaluations it was published with.\n")
    if results:
        out.append("Grasp success rate, pooled over evaluation runs, with 95% Wilson intervals.\n")
        out.append("| shift | objects | episodes | success | 95% interval |\n|---|---|---|---|---|")
        for r in results:
            out.append(
                f"| {r['shift']} | {r['split']} | {r['episodes']} | {_pct(r['rate'])} | "
                f"{_pct(r['ci_low'])} - {_pct(r['ci_high'])} |"
            )
        out.append("")
    else:
        out.append(f"Not evaluated yet: `nsl eval --checkpoint ckpt:{entry.ref} --shift {entry.shift}`.\n")

    out.append("## Files\n")
    out.append(
        f"- `{WEIGHTS_FILE}`: the Q-network weights (safetensors)\n"
        f"- `{CONFIG_FILE}`: model and training configuration, enough to rebuild the network\n"
        "- `README.md`: this card, generated from the nsl catalog\n"
    )
    return "\n".join(out)
