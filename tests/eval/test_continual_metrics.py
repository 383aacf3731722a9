"""Continual-learning metrics on hand-made performance matrices."""

from __future__ import annotations

import json

import pytest

from nsl.errors import ConfigError, CorruptDataError
from nsl.eval import PerformanceMatrix, Rate, SuccessRate, continual_metrics, curve_auc

TASKS = ["base", "A", "B"]
STAGES = ["init", "A", "B"]
R = [[0.80, 0.30, 0.40], [0.70, 0.90, 0.50], [0.75, 0.60, 0.85]]


def _matrix(**kw) -> PerformanceMatrix:
    return PerformanceMatrix(TASKS, STAGES, R, **kw)


def test_metrics_on_a_hand_made_matrix():
    m = continual_metrics(_matrix(single={"A": 0.8, "B": 0.9}, reference={"A": 0.2, "B": 0.5}))
    assert m.trained_at == {"base": 0, "A": 1, "B": 2}
    assert m.average_final_success == pytest.approx((0.75 + 0.60 + 0.85) / 3)
    assert m.final == pytest.approx({"base": 0.75, "A": 0.60, "B": 0.85})
    assert m.own_stage == pytest.approx({"base": 0.80, "A": 0.90, "B": 0.85})
    # forgetting: best success since the task's own stage (before the last) minus final
    assert m.forgetting["base"] == pytest.approx(0.80 - 0.75)
    assert m.forgetting["A"] == pytest.approx(0.90 - 0.60)
    assert m.forgetting["B"] is None  # trained at the last stage
    assert m.average_forgetting == pytest.approx((0.05 + 0.30) / 2)
    assert m.backward_transfer["base"] == pytest.approx(-0.05) and m.backward_transfer["A"] == pytest.approx(-0.30)
    assert m.backward_transfer["B"] is None
    assert m.average_backward_transfer == pytest.approx(-0.175)
    assert m.forward_transfer["A"] == pytest.approx(0.90 - 0.20) and m.forward_transfer["B"] == pytest.approx(0.35)
    assert m.forward_transfer["base"] is None
    assert m.zero_shot_transfer["A"] == pytest.approx(0.0) and m.zero_shot_transfer["B"] == pytest.approx(0.10)
    assert m.vs_base["A"] == pytest.approx(0.60) and m.vs_base["B"] == pytest.approx(0.45)
    assert m.vs_single["A"] == pytest.approx(0.10) and m.vs_single["B"] == pytest.approx(-0.05)
    assert m.final_vs_single["A"] == pytest.approx(-0.20) and m.final_vs_single["base"] is None


def test_best_earlier_forgetting_differs_from_end_of_own_training():
    # A improves after its own stage (0.9 -> 0.95 at stage 2) and ends at 0.6
    m = continual_metrics(
        PerformanceMatrix(
            ["base", "A", "B", "C"],
            ["init", "A", "B", "C"],
            [[0.8, 0.3, 0.4, 0.2], [0.8, 0.9, 0.5, 0.3], [0.8, 0.95, 0.8, 0.3], [0.8, 0.6, 0.8, 0.7]],
        )
    )
    assert m.forgetting["A"] == pytest.approx(0.35)  # issue's definition: best earlier - final
    assert m.forgetting_end["A"] == pytest.approx(0.30)  # Continual World's: end of own training - final
    assert m.forgetting["B"] == pytest.approx(0.0) and m.forgetting["base"] == pytest.approx(0.0)
    assert m.zero_shot_transfer["C"] == pytest.approx(0.1)


def test_forward_transfer_from_curves():
    assert curve_auc([0, 10, 20], [0.0, 0.5, 1.0]) == pytest.approx(0.5)
    curves = {"A": {"steps": [0, 10, 20], "success": [0.6, 0.8, 0.8]}}  # AUC 0.75
    ref = {"A": {"steps": [0, 10, 20], "success": [0.0, 0.5, 0.5]}}  # AUC 0.375
    m = continual_metrics(_matrix(curves=curves, reference_curves=ref))
    assert m.forward_transfer_auc["A"] == pytest.approx((0.75 - 0.375) / (1 - 0.375))
    assert m.forward_transfer_auc["B"] is None and m.forward_transfer["A"] is None  # no references for those
    with pytest.raises(ConfigError, match="steps must increase"):
        curve_auc([0, 0, 1], [0.1, 0.2, 0.3])


def test_partial_matrix_grows_stage_by_stage(tmp_path):
    m = PerformanceMatrix(TASKS, [], [])
    with pytest.raises(ConfigError, match="no rows yet"):
        continual_metrics(m)
    m = m.with_stage("init", {"base": SuccessRate("base", 50, 40), "A": Rate(0.3, 50), "B": 0.4})
    m = m.with_stage("A", {"base": 0.7, "A": 0.9, "B": 0.5})
    path = tmp_path / "matrix.json"
    m.save(path)
    back = PerformanceMatrix.load(path)
    assert back == m and back.episodes[0] == (50, 50, None)
    assert back.rate(0, 0).ci == pytest.approx(Rate(0.8, 50).ci)
    partial = continual_metrics(back)
    assert partial.own_stage["A"] == pytest.approx(0.9) and partial.forgetting["A"] is None
    assert partial.final["B"] == pytest.approx(0.5) and partial.trained_at["B"] is None
    with pytest.raises(ConfigError, match=r"results for unknown tasks \['C'\]"):
        m.with_stage("B", {"C": 0.5})


def test_table_5_3_shape():
    md = continual_metrics(_matrix(single={"A": 0.8, "B": 0.9}, episodes=[[50] * 3] * 3)).markdown()
    lines = md.splitlines()
    assert lines[0] == "| task | continual | vs base | vs single | final | forgetting |"
    assert lines[2] == "| A | 90% [79-96] | +60 | +10 | 60% [46-72] | +30 |"
    assert lines[3].startswith("| B | 85% ") and lines[4].startswith("| base | 80% ")
    assert "Average final success 73%" in md


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"stages": ["init", "A", "A"]}, "repeat a task"),
        ({"stages": ["init", "A", "Z"]}, r"stages \['Z'\] are not among the matrix tasks"),
        ({"success": [[0.8, 30, 0.4], [0.7, 0.9, 0.5], [0.75, 0.6, 0.85]]}, r"values \[30.0\] outside \[0, 1\]"),
        ({"success": R[:2]}, "2 rows for 3 stages"),
        ({"base_task": "A"}, "cannot also be trained"),
    ],
)
def test_bad_matrices_are_rejected(kwargs, match):
    args = {"tasks": TASKS, "stages": STAGES, "success": R, **kwargs}
    with pytest.raises(ConfigError, match=match):
        PerformanceMatrix(**args)


def test_corrupt_matrix_file(tmp_path):
    path = tmp_path / "matrix.json"
    path.write_text('{"tasks": ["base"]')
    with pytest.raises(CorruptDataError, match="is not valid JSON"):
        PerformanceMatrix.load(path)
    path.write_text(json.dumps({"tasks": ["base"], "stages": ["init"]}))
    with pytest.raises(CorruptDataError, match=r"lacks \['success'\]"):
        PerformanceMatrix.load(path)
