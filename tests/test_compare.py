"""``nsl compare`` / ``nsl.compare``: two sides' catalogued per-scene outcomes, hand-made (no simulator), give the
per-shift paired differences, the aggregates across shifts and P(A > B) that can be computed by hand."""

from __future__ import annotations

import json

import numpy as np
import pytest
from rliable import metrics

from nsl.catalog import Catalog, DataUse
from nsl.errors import ConfigError, UnknownReferenceError
from nsl.stats import hierarchical_difference, hierarchical_gain
from tests.catalog.catalog_factories import make_dataset, weights_file
from tests.conftest import run_cli

SCENES = 2000  # the evaluations' scene seed; 8 episodes each
SHIFTS = ("harsh_lighting", "base")
# side A: target collections grasp-harsh v1 and v2, training seeds 0 and 1 on each; side B: one checkpoint
A_RUNS = {  # name: (collection version, training seed, {shift: outcomes per scene})
    "ft-c1-s0": (1, 0, {"harsh_lighting": "11110000", "base": "11111000"}),  # 4/8, 5/8
    "ft-c1-s1": (1, 1, {"harsh_lighting": "11101100", "base": "11111100"}),  # 5/8, 6/8
    "ft-c2-s0": (2, 0, {"harsh_lighting": "11111100", "base": "11111110"}),  # 6/8, 7/8
    "ft-c2-s1": (2, 1, {"harsh_lighting": "10101000", "base": "11110000"}),  # 3/8, 4/8
}
B_RUN = {"harsh_lighting": "10100000", "base": "11110110"}  # 2/8, 6/8
A_SCORES = {"harsh_lighting": [0.5, 0.625, 0.75, 0.375], "base": [0.625, 0.75, 0.875, 0.5]}
B_SCORES = {"harsh_lighting": [0.25], "base": [0.75]}


def _outcomes(text: str) -> list[int]:
    return [int(c) for c in text]


def _checkpoint(cat: Catalog, tmp_path, name: str, value: float, version: int | None, seed: int | None):
    """A tiny catalogued checkpoint trained 50/50 on grasp-base and grasp-harsh@v``version`` with ``seed``."""
    data = [] if version is None else [DataUse("grasp-base", 1, 0.5), DataUse("grasp-harsh", version, 0.5)]
    config = {"step": 100, "training": {} if seed is None else {"seed": seed}}
    return cat.save_checkpoint(name, 100, weights_file(tmp_path, value, name), config, data=data, shift="base")


def _evaluate(cat: Catalog, entry, shift: str, outcomes: str, seed: int = SCENES) -> None:
    cat.add_evaluation(
        entry.id, shift, episodes=len(outcomes), successes=outcomes.count("1"), seed=seed, extra={"outcomes": outcomes}
    )


@pytest.fixture
def catalog(tmp_path):
    """Side A's four runs and side B's one, each evaluated on both shifts on the same 8 scenes."""
    with Catalog() as cat:
        make_dataset(cat, "grasp-base", 1, "base", 10)
        for v in (1, 2):
            make_dataset(cat, "grasp-harsh", v, "harsh_lighting", 10)
        for i, (name, (version, seed, per_shift)) in enumerate(A_RUNS.items()):
            entry = _checkpoint(cat, tmp_path, name, float(i + 1), version, seed)
            for shift, outcomes in per_shift.items():
                _evaluate(cat, entry, shift, outcomes)
        base = _checkpoint(cat, tmp_path, "base0", 0.5, None, 0)
        for shift, outcomes in B_RUN.items():
            _evaluate(cat, base, shift, outcomes)
        yield cat


A_REFS = ",".join(f"ckpt:{n}" for n in A_RUNS)


def _compare(tmp_path, a=A_REFS, b="ckpt:base0", **kw):
    import nsl

    return nsl.compare(a, b, shift=",".join(SHIFTS), out=tmp_path / "out", reps=400, **kw)


def test_per_shift_differences_are_the_hand_computed_ones_with_hierarchical_gain_intervals(catalog, tmp_path):
    got = _compare(tmp_path)
    assert list(got.shifts) == list(SHIFTS)
    hand = {"harsh_lighting": (0.5625 - 0.25), "base": (0.6875 - 0.75)}
    for shift, d in hand.items():
        row = got.shifts[shift]
        assert (row.seed, row.episodes) == (SCENES, 8)
        assert row.difference.mean == pytest.approx(d)
        assert row.rate_a.mean == pytest.approx(np.mean(A_SCORES[shift])) and row.rate_b.mean == B_SCORES[shift][0]
        assert row.runs_a == tuple(A_SCORES[shift]) and row.runs_b == tuple(B_SCORES[shift])
        assert row.difference.low < row.difference.mean < row.difference.high  # contains the point, not degenerate
        # grouped as recorded: (collections, seeds, scenes) = (2, 2, 8), paired with B's scenes
        ft = [[_outcomes(A_RUNS[f"ft-c{c}-s{s}"][2][shift]) for s in (0, 1)] for c in (1, 2)]
        ref = hierarchical_gain(ft, _outcomes(B_RUN[shift]), n_boot=400)
        assert (row.difference.low, row.difference.high) == (ref.low, ref.high)
        assert (row.difference.collections, row.difference.seeds, row.difference.scenes) == (2, 2, 8)
        assert row.covers == "8 scenes (paired); A: 2 seeds x 2 collections; B: 1 run, fixed"
    assert got.a.collections == ("grasp-harsh@v1", "grasp-harsh@v2") and got.a.groups == ((0, 1), (2, 3))


def test_aggregates_and_probability_of_improvement_are_the_hand_computed_and_rliable_values(catalog, tmp_path):
    got = _compare(tmp_path)
    a, b = got.aggregates_a, got.aggregates_b
    # A's eight run-shift scores: sorted .375 .5 .5 .625 .625 .75 .75 .875; the middle half is .5 .625 .625 .75
    assert a["iqm"].value == pytest.approx(0.625)
    assert a["mean"].value == pytest.approx((0.5625 + 0.6875) / 2)
    assert a["optimality_gap"].value == pytest.approx(1 - 0.625)
    assert b["iqm"].value == pytest.approx(0.5) and b["mean"].value == pytest.approx(0.5)
    assert b["optimality_gap"].value == pytest.approx(0.5)
    # P(A > B): harsh lighting, every A run beats 0.25 (1); base, vs 0.75: one above, one tie, two below (1.5/4)
    assert got.improvement.value == pytest.approx((1.0 + 0.375) / 2)
    sa = np.array([A_SCORES[s] for s in SHIFTS]).T  # (runs, shifts), rliable's layout
    sb = np.array([B_SCORES[s] for s in SHIFTS]).T
    assert a["iqm"].value == pytest.approx(metrics.aggregate_iqm(sa))
    assert a["mean"].value == pytest.approx(metrics.aggregate_mean(sa))
    assert a["optimality_gap"].value == pytest.approx(metrics.aggregate_optimality_gap(sa, gamma=1.0))
    assert got.improvement.value == pytest.approx(metrics.probability_of_improvement(sa, sb))
    for e in (a["iqm"], a["mean"], a["optimality_gap"], got.improvement):
        assert e.low <= e.value <= e.high and e.low < e.high, e  # contains the point, not degenerate
    assert b["iqm"].low == b["iqm"].high == 0.5  # one run: nothing to resample between runs
    # the gap below the base's base-task level, 0.75: A's scores clipped at .75 average .609375 -> gap .140625
    low = _compare(tmp_path, gap_level=0.75).aggregates_a["optimality_gap"]
    assert low.value == pytest.approx(0.140625) == metrics.aggregate_optimality_gap(sa, gamma=0.75)
    with pytest.raises(ConfigError, match="gap_level 1.5 must be a success rate"):
        _compare(tmp_path, gap_level=1.5)


def test_the_cli_prints_rows_and_aggregates_and_writes_the_plot_and_json(catalog, tmp_path, capsys):
    out = tmp_path / "cli"
    code = run_cli("compare", A_REFS, "base0", "--shift", "harsh_lighting,base", "--out", str(out), "--reps", "300")
    text = capsys.readouterr().out
    assert code == 0, text
    lines = text.splitlines()
    harsh = next(line for line in lines if line.startswith("harsh_lighting "))
    base = next(line for line in lines if line.startswith("base "))
    assert "2000 x 8" in harsh and "56.2 [" in harsh and "25.0 [" in harsh and "+31.2 [" in harsh
    assert "-6.2 [" in base and "75.0 [" in base
    assert any(line.strip().startswith("IQM") and "A 62.5 [" in line and "B 50.0 [" in line for line in lines)
    assert any(line.strip().startswith("P(A > B)") and "0.69 [" in line for line in lines)
    assert (out / "profile.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    record = json.loads((out / "compare.json").read_text())
    assert record["shifts"]["harsh_lighting"]["difference"]["mean"] == pytest.approx(0.3125)
    assert record["aggregates"]["probability_of_improvement"]["value"] == pytest.approx(0.6875)
    assert record["profile_curves"]["a"]["profile"][0] == 1.0  # every score of A is above 0
    assert len(record["profile_curves"]["taus"]) == len(record["profile_curves"]["b"]["high"]) == 101


def test_sides_evaluated_on_other_scenes_fail_in_one_line_that_says_how_to_match_them(catalog, tmp_path, capsys):
    other = _checkpoint(catalog, tmp_path, "other", 9.0, None, 0)
    _evaluate(catalog, other, "harsh_lighting", "11000000", seed=1000)
    _evaluate(catalog, other, "base", "11000000")
    with pytest.raises(ConfigError, match="not evaluated on the same scenes on harsh_lighting") as err:
        _compare(tmp_path, b="ckpt:other")
    message = str(err.value)
    assert "\n" not in message and "ckpt:other@100 on seed 1000 x 8" in message
    assert "`nsl eval --checkpoint ckpt:other@100 --shift harsh_lighting --episodes 8 --seed 2000`" in message
    code = run_cli("compare", A_REFS, "ckpt:other", "--shift", "harsh_lighting", "--out", str(tmp_path / "o"))
    err_text = capsys.readouterr().err
    assert code == 2 and err_text.count("\n") == 1 and "not evaluated on the same scenes" in err_text


def test_a_missing_evaluation_names_the_checkpoint_shift_and_eval_command(catalog, tmp_path):
    late = _checkpoint(catalog, tmp_path, "late", 7.0, None, 0)
    _evaluate(catalog, late, "harsh_lighting", "11100000")
    with pytest.raises(UnknownReferenceError, match=r"ckpt:late@100 has no evaluation on base") as err:
        _compare(tmp_path, b="ckpt:late")
    assert "`nsl eval --checkpoint ckpt:late@100 --shift base --episodes 8 --seed 2000`" in str(err.value)
    with pytest.raises(UnknownReferenceError, match=r"seed 3000, 8 episodes.*--seed 3000"):
        _compare(tmp_path, seed=3000, episodes=8)


def test_several_runs_on_side_b_use_the_paired_two_sided_bootstrap_and_say_what_is_pooled(catalog, tmp_path):
    b_runs = {
        "b-s0": {"harsh_lighting": "10100000", "base": "11110110"},
        "b-s1": {"harsh_lighting": "11000010", "base": "01110111"},
    }
    for i, (name, per_shift) in enumerate(b_runs.items()):
        entry = _checkpoint(catalog, tmp_path, name, 20.0 + i, None, i)  # no training data recorded
        for shift, outcomes in per_shift.items():
            _evaluate(catalog, entry, shift, outcomes)
    got = _compare(tmp_path, b="ckpt:b-s0,ckpt:b-s1", labels=("recipe", "baseline"))
    row = got.shifts["harsh_lighting"]
    assert row.difference.mean == pytest.approx(0.5625 - 0.3125)
    assert row.difference.low < row.difference.mean < row.difference.high
    assert got.b.pooled == "ckpt:b-s0@100 records no training data"
    assert "B: 2 runs as seeds of one collection (ckpt:b-s0@100 records no training data)" in row.covers
    ox = np.array([[_outcomes(A_RUNS[f"ft-c{c}-s{s}"][2]["harsh_lighting"]) for s in (0, 1)] for c in (1, 2)])
    oy = np.array([[_outcomes(v["harsh_lighting"]) for v in b_runs.values()]])
    ref = hierarchical_difference(ox, oy, n_boot=400)
    assert (row.difference.mean, row.difference.low, row.difference.high) == (ref.mean, ref.low, ref.high)
    # P(A > B) over the 4 x 2 pairs: harsh lighting 7.5/8 (A's 0.375 ties B's 0.375), base 3/8 (B: 0.75 twice)
    assert got.improvement.value == pytest.approx((7.5 / 8 + 3 / 8) / 2)


def test_hierarchical_difference_is_hierarchical_gain_with_one_run_on_b_and_antisymmetric():
    rng = np.random.default_rng(3)
    a = (rng.random((2, 3, 40)) < 0.6).astype(float)
    b = (rng.random((1, 2, 40)) < 0.4).astype(float)
    one = hierarchical_difference(a, b[:, :1], n_boot=500)
    ref = hierarchical_gain(a, b[0, 0], n_boot=500)
    assert (one.mean, one.low, one.high) == (ref.mean, ref.low, ref.high)
    ab, ba = hierarchical_difference(a, b, n_boot=500), hierarchical_difference(b, a, n_boot=500)
    assert ab.mean == pytest.approx(a.mean() - b.mean()) and ba.mean == pytest.approx(-ab.mean)
    assert ab.low < ab.mean < ab.high and (ab.collections, ab.seeds, ab.scenes) == (2, 3, 40)
    # B's seeds vary, so the interval is wider than when B's mean over its seeds is taken as one fixed base
    fixed = hierarchical_gain(a, b.mean(axis=(0, 1)), n_boot=500)
    assert ab.high - ab.low > fixed.high - fixed.low
    with pytest.raises(ValueError, match="same scenes"):
        hierarchical_difference(a, b[:, :, :30])
