"""`write_report`: Markdown with the study's table shapes, valid PNGs, atomic writes."""

from __future__ import annotations

import json

import pytest
from PIL import Image

from nsl.errors import CorruptDataError, UnknownReferenceError
from nsl.eval import (
    CurveRow,
    EarlyStopConfig,
    PerformanceMatrix,
    Rate,
    TierResults,
    TierRow,
    plot_curve,
    plot_tiers,
    read_curve,
    tiers_table,
    write_curve,
    write_report,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _curve():
    target = [0.43, 0.60, 0.80, 0.90, 0.70, 0.40]
    return [
        CurveRow(s, Rate(t, 50), Rate(0.86, 50), softopc=0.1 * t, td_error=abs(t - 0.9) + 0.05)
        for s, t in zip([0, 1000, 2000, 3000, 4000, 5000], target)
    ]


def _tiers():
    return TierResults(
        {
            "offset_gripper": TierRow(
                Rate(0.44, 50),
                {25: Rate(0.74, 50), 100: Rate(0.60, 50), 800: Rate(0.98, 50)},
                {"scratch": Rate(0.37, 50), "imagenet": Rate(0.47, 50)},
            ),
            "harsh_lighting": TierRow(
                Rate(0.32, 50),
                {25: Rate(0.23, 50), 100: Rate(0.52, 50), 800: Rate(0.63, 50)},
                {"scratch": Rate(0.04, 50)},
            ),
        }
    )


def _matrix():
    tasks = ["base", "harsh_lighting", "offset_gripper"]
    return PerformanceMatrix(
        tasks,
        ["init", "harsh_lighting", "offset_gripper"],
        [[0.86, 0.31, 0.47], [0.84, 0.63, 0.50], [0.87, 0.58, 0.91]],
        [[50] * 3] * 3,
        single={"harsh_lighting": 0.63, "offset_gripper": 0.98},
    )


def _assert_png(path, min_size=(300, 200)):
    assert path.read_bytes()[:8] == PNG_MAGIC
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        assert im.size[0] >= min_size[0] and im.size[1] >= min_size[1]


def test_report_writes_markdown_json_and_pngs(tmp_path):
    run = tmp_path / "run"
    write_curve(run / "finetune" / "curve.csv", _curve())
    (run / "finetune" / "early_stop.json").write_text(
        json.dumps({"config": EarlyStopConfig(patience=2).to_dict(), "references": {"scratch (800 attempts)": 0.37}})
    )
    _matrix().save(run / "matrix.json")
    _tiers().save(run / "tiers.json")
    res = write_report(run)

    assert res.markdown == run / "report" / "report.md"
    assert sorted(p.name for p in res.figures) == ["curve-finetune.png", "matrix.png", "tiers.png"]
    for p in res.figures:
        _assert_png(p)
    md = res.markdown.read_text()
    assert "![learning curve](curve-finetune.png)" in md and "![performance matrix](matrix.png)" in md
    # early-stopping table: eval with patience 2 stops at 5000 and keeps 3000
    assert "| criterion | chosen step | stopped at | target success |" in md
    assert "| eval | 3000 | 5000 | 90% [79-96] | 86% [74-93] | +0 | 0 |" in md
    # Table 5.3 shape
    assert "| task | continual | vs base | vs single | final | forgetting |" in md
    assert "| harsh_lighting | 63% [50-76] | +32 | +0 | 58% [44-71] | +5 |" in md
    # Table 5.2 shape, rows and comparison columns in the order given
    assert "| challenge | base | 25 | 100 | 800 | best (change) | scratch | imagenet |" in md
    assert "| offset gripper | 44% [31-58] | 74% [60-84] | 60% [46-72] | 98% [90-100] | 98% (+54) @800 |" in md
    assert md.index("offset gripper") < md.index("harsh lighting")
    numbers = json.loads(res.json.read_text())
    assert numbers["curves"]["finetune/curve.csv"]["choices"]["best"]["step"] == 3000
    assert numbers["continual"]["matrix.json"]["average_final_success"] == pytest.approx((0.87 + 0.58 + 0.91) / 3)
    assert "code_version" in numbers
    assert not list(run.rglob("*.tmp")), "a temporary file was left behind"


def test_report_reads_a_trainers_eval_jsonl(tmp_path):
    lines = [json.dumps({**r.to_dict(), "stop": False}) for r in _curve()]
    (tmp_path / "eval.jsonl").write_text("\n".join(['{"step": 0, "note": "no curve fields"}', *lines]) + "\n")
    res = write_report(tmp_path, out_dir=tmp_path / "out")
    assert [p.name for p in res.figures] == ["curve.png"] and res.sections == ["eval.jsonl"]
    assert "| best | 3000 |" in res.markdown.read_text()


def test_curve_csv_round_trips(tmp_path):
    rows = _curve() + [CurveRow(6000, None, None, auc=0.7)]
    write_curve(tmp_path / "curve.csv", rows)
    assert read_curve(tmp_path / "curve.csv") == rows
    header = (tmp_path / "curve.csv").read_text().splitlines()[0]
    assert header.startswith("step,target_success,target_ci_low,target_ci_high,target_episodes,base_success")


def test_tiers_json_round_trips_in_order(tmp_path):
    _tiers().save(tmp_path / "tiers.json")
    back = TierResults.load(tmp_path / "tiers.json")
    assert back == _tiers() and list(back.rows) == ["offset_gripper", "harsh_lighting"]
    assert back.comparison_names == ["scratch", "imagenet"] and back.tiers == [25, 100, 800]
    assert "| harsh lighting | 32% | 23% | 52% | 63% | 63% (+31) @800 | 4% | - |" in tiers_table(back, intervals=False)


def test_plot_curve_without_intervals_or_offline_columns(tmp_path):
    rows = [CurveRow(s, Rate(v)) for s, v in [(0, 0.2), (10, 0.5), (100000, 0.4)]]  # log-x span, no episodes
    _assert_png(plot_curve(rows, tmp_path / "c.png"))


def test_report_errors(tmp_path):
    with pytest.raises(UnknownReferenceError, match="run folder .* does not exist"):
        write_report(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(UnknownReferenceError, match="holds no curve.csv, eval.jsonl, matrix.json or tiers.json"):
        write_report(tmp_path / "empty")
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "curve.csv").write_text("steps,target_success\n1,0.5\n")
    with pytest.raises(CorruptDataError, match="has no 'step' column"):
        write_report(bad)
    (bad / "curve.csv").unlink()
    (bad / "tiers.json").write_text(json.dumps({"rows": [{"base": {"success_rate": 0.5}}]}))
    with pytest.raises(CorruptDataError, match="lacks the field 'shift'"):
        write_report(bad)


def test_tier_plot_takes_rates_of_zero_and_one(tmp_path):
    """At 0% or 100% the Wilson bound equals the rate up to rounding; the error bar must not go negative."""
    tiers = TierResults({"harsh_lighting": TierRow(Rate(0.0, 3), {4: Rate(1.0, 3), 8: Rate(0.0, 3)}, {})})
    out = plot_tiers(tiers, tmp_path / "tiers.png")
    assert out.stat().st_size > 0
