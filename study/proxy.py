"""The offline proxy of transfer, and ``suggest-base``: rank catalogued checkpoints as bases for a new task.

The proxy of a checkpoint for a task needs no training and no simulator: the checkpoint's Q-function is
run once over the transitions of the first K episodes of the task's data, and scored by how well it
separates transitions of successful episodes from those of failed ones::

    auc      Q-ranking AUC: P(Q of a success transition > Q of a failure transition), ties 1/2 (0.5 = chance)
    softopc  SoftOPC: mean Q on success transitions minus mean Q on all (Irpan et al. 2019)

(``nsl.eval.q_ranking_auc`` and ``soft_opc``; the same scores ``nsl train --early-stop`` uses.)  How well
the proxy predicts the measured advantage is measured, not assumed: ``nsl transfer`` reports Spearman's
rank correlation between them over its (source, target) pairs.

:func:`suggest_base` ranks candidates by the measured advantage where a transfer matrix has it (the
candidate is the checkpoint of a source task, and the new task is one of its targets), else by the proxy.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

from nsl.errors import ConfigError, UnknownReferenceError

PROXIES = ("auc", "softopc")


def proxy_scores(checkpoint_path: str | Path, view) -> dict[str, float]:
    """``{"auc", "softopc"}`` of a checkpoint's Q-function on a dataset view ({} without successes and failures)."""
    from nsl.learners import load_policy
    from nsl.services.scoring import offline_scorer

    return dict(offline_scorer(view, gamma=0.0, td=False)(load_policy(str(checkpoint_path))))


class ProxyCache:
    """Proxy scores by (checkpoint id, data content hash), kept in a JSON file (temporary file, then rename)."""

    def __init__(self, path: Path | None):
        self.path = path
        self.data: dict[str, dict[str, float]] = {}
        if path is not None and path.is_file():
            try:
                self.data = json.loads(path.read_text())
            except json.JSONDecodeError:
                self.data = {}  # a cache: recomputed when unreadable

    def scores(self, checkpoint_id: str, checkpoint_path: str | Path, view) -> dict[str, float]:
        key = f"{checkpoint_id}|{view.content_hash}"
        if key not in self.data:
            self.data[key] = proxy_scores(checkpoint_path, view)
            if self.path is not None:
                from nsl.workspace import atomic_write_json

                atomic_write_json(self.path, self.data)
        return self.data[key]


def target_view(data: str, episodes: int):
    """The first ``episodes`` episodes of a dataset reference ``[data:]NAME[@vN][:K]`` (at most K)."""
    from nsl.datasets import api

    ref = api.parse_ref(data)
    version = api.open_version(api.Ref(ref.name, ref.version))
    return version.view(0, min(episodes, ref.tier or version.num_episodes, version.num_episodes))


def _candidates(cat, refs: Sequence[str]):
    """The checkpoints named, or the newest checkpoint of every catalogued name (and the shipped base)."""
    from nsl.services.refs import resolve_init

    if refs:
        return [cat.resolve_checkpoint(r) for r in refs]
    out = {}
    base = resolve_init(cat, "ckpt:base")
    out[base.id] = base
    for name in dict.fromkeys(c.name for c in cat.checkpoints()):
        entry = cat.resolve_checkpoint(f"ckpt:{name}@latest")
        out.setdefault(entry.id, entry)
    return list(out.values())


def suggest_base(
    shift: str,
    data: str,
    *,
    episodes: int = 100,
    matrix=None,
    checkpoints: Sequence[str] = (),
    proxy: str = "auc",
    progress: bool = False,
):
    """Candidates ranked for learning ``shift`` from ``data``: measured advantage first, then ``proxy``."""
    from nsl.catalog import Catalog
    from nsl.collectors import parse_shift
    from nsl.curriculum import Candidate, rank_candidates

    if proxy not in PROXIES:
        raise ConfigError(f"proxy {proxy!r} is unknown; use one of {', '.join(PROXIES)}")
    if episodes < 2:
        raise ConfigError(f"--episodes {episodes} must be at least 2 (the proxy needs successes and failures)")
    task = parse_shift(shift).name
    view = target_view(data, episodes)
    measured = {}
    if matrix is not None and task in matrix.tasks:
        ids = {t: (c or {}).get("id") for t, c in (matrix.meta.get("checkpoints") or {}).items()}
        for src in matrix.tasks:
            if src != task and ids.get(src) and matrix.get(src, task) is not None:
                measured[ids[src]] = (matrix.get(src, task), matrix.interval.get((src, task)))
    cache = ProxyCache(None)
    out = []
    with Catalog() as cat:
        try:
            entries = _candidates(cat, checkpoints)
        except UnknownReferenceError as e:
            raise UnknownReferenceError(f"suggest-base: {e}") from None
    for i, entry in enumerate(entries):
        if progress:
            print(f"  scoring {i + 1}/{len(entries)} {entry.ref}", end="\r", flush=True)
        scores = cache.scores(entry.id, entry.path, view)
        a, ci = measured.get(entry.id, (None, None))
        note = "" if scores else f"{view.ref} lacks successes or failures"
        out.append(Candidate(f"ckpt:{entry.ref}", entry.id, entry.shift, a, ci, scores.get(proxy), note))
    if progress:
        print(" " * 80, end="\r")
    return rank_candidates(out), view.ref
