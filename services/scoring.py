"""Offline scores of a policy on held-out target episodes: SoftOPC, ranking AUC, TD error, average Q and FQE
(no simulator).

SoftOPC and AUC rank the Q-values of held-out transitions by their episode's
success.  The TD error compares Q(s, a) with the one-step Bellman target
r + gamma * (1 - done) * Q(s', a*), a* = CEM's maximum (each transition's CEM
noise is fixed, so evaluations differ only by the network); transitions whose
episode was truncated after them have no known target and are left out.
Lower is better.  The average Q-value of the held-out transitions (``q_mean``)
comes with them.  FQE (:mod:`nsl.learners.fqe`) fits the policy's value on the
same transitions, from the episodes' first states, and costs a fit per call,
so it is computed when it is the criterion or asked for.  ``nsl train
--criterion`` and the study's early-stopping curves both score with
:func:`offline_scorer`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from nsl import keys

TD_SEED = 2000  # CEM noise for the held-out next states: the same draw at every evaluation
CHUNK = 512  # transitions per batched Q-value call


def q_values(policy: Any, obs: dict[str, np.ndarray], actions: np.ndarray, chunk: int = CHUNK) -> np.ndarray:
    """The policy's Q-values of ``actions`` in ``obs``, in chunks of ``chunk`` transitions."""
    parts = [
        policy.q_values({k: v[i : i + chunk] for k, v in obs.items()}, actions[i : i + chunk])
        for i in range(0, len(actions), chunk)
    ]
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.float32)


def offline_scorer(
    view: Any, gamma: float, criterion: str | None = None, *, td: bool = True, fqe: Any = None
) -> Callable[[Any], dict[str, float]]:
    """``policy -> {"softopc", "auc", "q_mean", "td_error", "fqe"}`` on the held-out ``view``.

    Every score that is defined is returned: SoftOPC and AUC need both
    successful and failed held-out episodes.  A score that cannot be computed
    is an error only when it is ``criterion``, the one early stopping follows.
    ``td=False`` skips the TD error (its CEM maximisation is the costly part).
    ``fqe`` (an :class:`~nsl.learners.fqe.FQEConfig`; default with criterion
    ``fqe``) adds FQE's estimate of the success rate.
    """
    from nsl.datasets import api
    from nsl.errors import ConfigError
    from nsl.eval import q_ranking_auc, soft_opc, td_error

    arrays = view.episodes_arrays()
    labels = api.frame_labels(arrays)
    obs = {"image": arrays[keys.OBS_IMAGE], "state": arrays[keys.OBS_STATE]}
    live, known = labels.live, labels.known
    actions = arrays[keys.ACTION]

    if fqe is None and criterion == "fqe":
        from nsl.learners.fqe import FQEConfig

        fqe = FQEConfig()
    first = np.flatnonzero(labels.first)

    def score(policy: Any) -> dict[str, float]:
        q = q_values(policy, obs, actions)
        out: dict[str, float] = {"q_mean": float(np.mean(q))} if len(q) else {}
        for key, fn in (("softopc", soft_opc), ("auc", q_ranking_auc)):
            try:
                out[key] = fn(q, labels.success)
            except ConfigError:  # e.g. no failed episode held out: only fatal when it is the criterion
                if criterion == key:
                    raise
        if not (td or fqe is not None):
            return out
        best = np.zeros_like(actions)  # the policy's action at each live frame's next state
        value = np.zeros(len(q))
        if len(live):
            nxt = {"image": obs["image"][live + 1], "state": obs["state"][live + 1]}
            best[live] = policy(nxt, rngs=[np.random.default_rng([TD_SEED, int(j)]) for j in live])
            value[live] = q_values(policy, nxt, best[live])
        if td:
            target = labels.reward + gamma * (~labels.done) * value
            out["td_error"] = td_error(q[known], target[known])
        if fqe is not None:
            out["fqe"] = _fqe(policy, known, live, first, best, fqe)
        return out

    def _fqe(policy: Any, known: np.ndarray, live: np.ndarray, first: np.ndarray, best: np.ndarray, config) -> float:
        from nsl.learners.fqe import network_fqe

        rows = np.flatnonzero(known)
        following = np.isin(rows, live)
        nxt = np.where(following, rows + 1, rows)  # a terminal frame's next state is never used (done)
        next_actions = np.where(following[:, None], best[rows], actions[rows])
        start = {k: v[first] for k, v in obs.items()}
        start_actions = policy(start, rngs=[np.random.default_rng([TD_SEED, int(j)]) for j in first])
        return network_fqe(
            policy.net,
            ({k: v[rows] for k, v in obs.items()}, actions[rows]),
            ({k: v[nxt] for k, v in obs.items()}, next_actions),
            (start, start_actions),
            labels.reward[rows],
            labels.done[rows],
            config,
        ).value

    return score
