"""Fitted Q evaluation recovers a policy's value, computed by hand, from data another policy logged."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nsl.errors import ConfigError
from nsl.learners.fqe import FQEConfig, fitted_q_evaluation

# A two-step MDP.  An episode starts in A or B (half each).  Action 0 in A, or 1 in B, leads to C; the other
# action leads to D.  In C, action 0 grasps with success 0.8 and action 1 with 0.1; in D, action 0 with 0.3 and
# action 1 with 0.5.  The evaluated policy takes 0 in A, 1 in B, 0 in C and 0 in D: it always reaches C and
# grasps with action 0, so its success rate is 0.8.  The data come from a uniformly random behaviour policy,
# whose own success rate is (0.8 + 0.1 + 0.3 + 0.5) / 4 = 0.425, in exact proportions (the empirical MDP is
# the true one).
A, B, C, D = range(4)
PI = {A: 0, B: 1, C: 0, D: 0}
GRASP = {(C, 0): 0.8, (C, 1): 0.1, (D, 0): 0.3, (D, 1): 0.5}
TRUE_VALUE = 0.8


def _logged(copies: int = 10):
    s, a, r, d, s2 = [], [], [], [], []
    for start in (A, B):
        for first in (0, 1):
            mid = C if (start == A) == (first == 0) else D
            for second in (0, 1):
                successes = round(GRASP[(mid, second)] * copies)
                for k in range(copies):
                    s += [start, mid]
                    a += [first, second]
                    r += [0.0, float(k < successes)]
                    d += [False, True]
                    s2 += [mid, mid]  # the terminal transition's next state is never used (done)
    return (np.array(x) for x in (s, a, r, d, s2))


def _tabular(s, a, s2):
    """Logits Q[state, action] as one table; the policy's actions from PI."""
    table = torch.zeros(4, 2, requires_grad=True)
    next_a = torch.tensor([PI[int(x)] for x in s2])
    s, a, s2 = (torch.as_tensor(x) for x in (s, a, s2))
    starts = torch.tensor([A, B])

    def logits(kind, rows):
        if kind == "initial":
            return table[starts, torch.tensor([PI[A], PI[B]])]
        ss, aa = (s, a) if kind == "data" else (s2, next_a)
        return table[ss, aa] if rows is None else table[ss[rows], aa[rows]]

    return logits, table


def test_fqe_recovers_the_hand_computed_value_of_a_policy_the_data_did_not_follow():
    s, a, r, d, s2 = _logged()
    assert r.sum() / (r.size / 2) == pytest.approx(0.425)  # the behaviour policy's success in the data
    logits, table = _tabular(s, a, s2)
    result = fitted_q_evaluation(logits, [table], r, d, FQEConfig(iterations=4, steps=60, lr=0.5))
    assert result.value == pytest.approx(TRUE_VALUE, abs=0.01)
    assert result.values[0] < result.value  # one backup has not reached the start yet
    probs = torch.sigmoid(table).detach()
    assert probs[C, 1] == pytest.approx(0.1, abs=0.01) and probs[D, 1] == pytest.approx(0.5, abs=0.01)


def test_fqe_with_minibatches_and_bad_settings():
    s, a, r, d, s2 = _logged()
    logits, table = _tabular(s, a, s2)
    result = fitted_q_evaluation(logits, [table], r, d, FQEConfig(iterations=4, steps=100, lr=0.1, batch_size=80))
    assert result.value == pytest.approx(TRUE_VALUE, abs=0.04)  # 0.80 here; minibatch noise on the last steps
    with pytest.raises(ConfigError, match="gamma"):
        FQEConfig(gamma=0.0)
    with pytest.raises(ConfigError, match="one reward and one done flag per transition"):
        fitted_q_evaluation(logits, [table], r, d[:-1])
