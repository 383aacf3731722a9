"""Early stopping without a simulator: each criterion's pick in the `early-stop` study, judged on unseen scenes.

The study (``nsl study run early-stop``) fine-tunes the shipped base for 10,000 steps on every shift and keeps
a checkpoint every 500 steps, with the simulator on 200 selection scenes and the offline criteria (SoftOPC,
Q-ranking AUC, TD error, average Q, FQE) on held-out target episodes.  This script judges the picks:

``evaluate STUDY`` (resumable: outcomes append to ``$NSL_HOME/studies/STUDY/judged.jsonl``)
  * every kept checkpoint of every finished run on the oracle's scenes: 500 test-object scenes of its shift,
    seed ``nsl.REPORTING_SCENES`` (2000), which no criterion saw; the best there is the oracle's pick;
  * each criterion's pick, the baselines' (the recipe's fixed 2,000 steps, the last step) and the oracle's on
    the final reporting scenes (seed 51425, 500 scenes), on the shift and on the base task.
  It costs 21 x 500 + about 6 x 1,000 episodes per run: about 12 minutes per run on this 2-core machine.

``refit STUDY --criterion NAME`` (resumable): for every finished run at the plan's tier, the step count that
  criterion chose on the run (trained without its held-out 20%) is used to train the run again, the same seed and
  recipe, on all its target episodes (no held-out split); the refit checkpoint is scored on the final reporting
  scenes, the shift and the base task, beside the pick.  About 5 minutes per run at a pick near 2,000 steps.

``export STUDY --out DIR``: copies the curves and the judged outcomes into DIR (the committed records);
``curves STUDY --out DIR`` copies only the finished runs' curves, while the study still runs.

``report DIR``: from the committed records alone, prints the criteria table (criterion x shift: chosen steps,
reporting success, regret against the oracle with its hierarchical interval over seeds and scenes, Spearman's
rho against the oracle's scenes, the base task at the pick) and draws the Fig. 5.7 curves to DIR/curves.png.

    python scripts/experiments/early_stopping.py evaluate early-stop --workers 2
    python scripts/experiments/early_stopping.py refit early-stop --criterion softopc
    python scripts/experiments/early_stopping.py export early-stop --out docs/experiments/early-stopping
    python scripts/experiments/early_stopping.py report docs/experiments/early-stopping
"""

from __future__ import annotations

import argparse
import functools
import json
import shutil
from pathlib import Path

ORACLE_EPISODES = 500
REPORTING_EPISODES = 500
JUDGED = "judged.jsonl"


# --- the records --------------------------------------------------------------------------------------------------


def refit_tag(criterion: str, tag: str) -> str:
    """The refit of run ``tag`` to the step count ``criterion`` chose: its records' tag and checkpoint suffix."""
    return f"refit-{criterion}-{tag}"


def judged_tag(tag: str, step: int) -> str:
    """Step 0 is the base policy itself, the same for every run: judged once, under ``base``."""
    return "base" if step == 0 else tag


def read_judged(path: Path) -> dict[tuple, list[bool]]:
    """{(tag, step, task, seed, episodes): outcomes}; a line cut short by a crash is ignored."""
    out = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                d = json.loads(line)
            except json.JSONDecodeError:
                continue
            out[(d["tag"], d["step"], d["task"], d["seed"], d["episodes"])] = [c == "1" for c in d["outcomes"]]
    return out


def append_judged(path: Path, key: tuple, outcomes: list[bool]) -> None:
    tag, step, task, seed, episodes = key
    line = {"tag": tag, "step": step, "task": task, "seed": seed, "episodes": episodes}
    line["outcomes"] = "".join("1" if o else "0" for o in outcomes)
    with open(path, "a") as f:
        f.write(json.dumps(line) + "\n")
        f.flush()


def plan_of(study: str):
    from nsl.study.driver import _load

    return _load(study)


def runs_of(plan) -> list:
    from nsl.study.units import early_stop_runs

    return early_stop_runs(plan)


def judged_runs(records: Path, meta: dict, judged: dict) -> list:
    oracle_n, reporting_n = meta["oracle_episodes"], meta["reporting_episodes"]
    """The runs whose curve ended and whose oracle scenes are all evaluated, as JudgedRun."""
    from nsl.eval.records import read_curve
    from nsl.eval.selection import JudgedRun

    out = []
    for r in meta["runs"]:
        path = records / "curves" / f"{r['tag']}.csv"
        if not path.is_file():
            continue
        rows = read_curve(path)
        if not rows or rows[-1].step != meta["steps"]:
            continue
        oracle = {
            s.step: judged.get((judged_tag(r["tag"], s.step), s.step, "target", meta["oracle_seed"], oracle_n))
            for s in rows
        }
        if any(v is None for v in oracle.values()):
            continue
        reporting = {}
        for (tag, step, task, seed, n), o in judged.items():
            if tag == judged_tag(r["tag"], step) and seed == meta["reporting_seed"] and n == reporting_n:
                reporting[(step, task)] = o
        out.append(JudgedRun(r["tag"], r["label"], r["seed"], rows, oracle, reporting))
    return out


def meta_of(plan, oracle_episodes: int = ORACLE_EPISODES, reporting_episodes: int = REPORTING_EPISODES) -> dict:
    from nsl import FINAL_REPORTING_SCENES, REPORTING_SCENES

    es = plan.early_stop
    runs = []
    for r in runs_of(plan):
        label = r.shift if r.episodes == es.episodes and not r.base else f"{r.shift} n{r.episodes}"
        if r.base:
            label += " base " + "+".join(r.base)
        runs.append({"tag": r.tag, "shift": r.shift, "label": label, "seed": r.seed, "episodes": r.episodes})
    return {
        "study": plan.name,
        "steps": es.steps,
        "every": es.every,
        "patience": es.patience,
        "fixed_step": plan.finetune.steps,
        "oracle_seed": REPORTING_SCENES,
        "oracle_episodes": oracle_episodes,
        "reporting_seed": FINAL_REPORTING_SCENES,
        "reporting_episodes": reporting_episodes,
        "runs": runs,
    }


# --- evaluate -----------------------------------------------------------------------------------------------------


def evaluate(study: str, workers: int, episodes: tuple[int, int], only: list[str]) -> None:
    from nsl import workspace
    from nsl.eval.records import read_curve
    from nsl.eval.selection import needed_reporting

    plan = plan_of(study)
    meta = meta_of(plan, *episodes)
    folder = workspace.home() / "studies" / study
    path = folder / JUDGED
    judged = read_judged(path)

    def score(run: str, step: int, task: str, seed: int, episodes: int) -> None:
        tag = judged_tag(run, step)
        key = (tag, step, task, seed, episodes)
        if key in judged:
            return
        ckpt = workspace.home() / "runs" / f"{study}-{run}" / "checkpoints" / f"step-{step:09d}"
        if step == 0:
            ckpt = base_checkpoint(plan)
        outcomes = scenes_outcomes(ckpt, task if task != "target" else shift_of[run], seed, episodes, workers)
        append_judged(path, key, outcomes)
        judged[key] = outcomes
        print(f"{tag} step {step} {task} seed {seed}: {100 * sum(outcomes) / len(outcomes):.1f}%", flush=True)

    shift_of = {r["tag"]: r["shift"] for r in meta["runs"]}
    full = episodes == (ORACLE_EPISODES, REPORTING_EPISODES)
    records = folder / ("judging" if full else f"judging-{episodes[0]}x{episodes[1]}")
    (records / "curves").mkdir(parents=True, exist_ok=True)
    for r in meta["runs"]:
        if only and r["tag"] not in only:
            continue
        curve = workspace.home() / "runs" / f"{study}-{r['tag']}" / "curve.csv"
        if not curve.is_file():
            continue
        rows = read_curve(curve)
        if not rows or rows[-1].step != meta["steps"]:
            print(f"{r['tag']}: still training (step {rows[-1].step if rows else 0}); skipped", flush=True)
            continue
        shutil.copyfile(curve, records / "curves" / f"{r['tag']}.csv")
        for row in rows:
            score(r["tag"], row.step, "target", meta["oracle_seed"], meta["oracle_episodes"])
    runs = judged_runs(records, meta, judged)
    for tag, steps in needed_reporting(runs, meta["patience"], meta["fixed_step"]).items():
        for step in sorted(steps):
            for task in ("target", "base"):
                score(tag, step, task, meta["reporting_seed"], meta["reporting_episodes"])
    (records / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    shutil.copyfile(path, records / JUDGED)
    print(f"{len(runs)} of {len(meta['runs'])} runs judged; records in {records}")


def refit(study: str, criterion: str, workers: int, only: list[str]) -> None:
    """Train each finished plan-tier run again on all its target data, to the step count ``criterion`` chose
    on it, and score that checkpoint on the reporting scenes (the records go where ``evaluate`` puts them)."""
    from dataclasses import replace

    from nsl import workspace
    from nsl.eval.records import read_curve
    from nsl.eval.selection import curve_picks
    from nsl.study.actions import base_sources, is_done, run_unit
    from nsl.study.units import build_units

    plan = plan_of(study)
    meta = meta_of(plan)
    units = build_units(plan, study, base_sources(plan))
    folder = workspace.home() / "studies" / study
    path = folder / JUDGED
    judged = read_judged(path)
    records = folder / "judging"
    records.mkdir(parents=True, exist_ok=True)
    for r in meta["runs"]:
        if r["label"] != r["shift"] or (only and r["tag"] not in only):  # the extra runs are not refitted
            continue
        curve = workspace.home() / "runs" / f"{study}-{r['tag']}" / "curve.csv"
        rows = read_curve(curve) if curve.is_file() else []
        if not rows or rows[-1].step != meta["steps"]:
            continue
        picks = curve_picks(rows, meta["patience"], meta["fixed_step"])
        if criterion not in picks:
            raise SystemExit(f"no criterion {criterion!r} on run {r['tag']}; choose one of {', '.join(sorted(picks))}")
        step = picks[criterion]
        tag = refit_tag(criterion, r["tag"])
        keys = [(tag, step, task, meta["reporting_seed"], meta["reporting_episodes"]) for task in ("target", "base")]
        if all(k in judged for k in keys):
            continue
        if step == 0:  # the criterion kept the base policy: refitting trains nothing, and the base may be judged
            ckpt = base_checkpoint(plan)
            for key in keys:
                known = judged.get(("base", 0, *key[2:]))
                if key not in judged and known is not None:
                    append_judged(path, key, known)
                    judged[key] = known
        else:
            unit = units[f"train:{r['tag']}"]
            params = {**unit.params, "checkpoint": f"{study}-{tag}", "steps": step, "monitor": None}
            job = replace(unit, name=f"train:{tag}", params=params)
            if not is_done(job):
                print(f"{tag}: training {step} steps on all {r['episodes']} target episodes", flush=True)
                run_unit(job, workers=workers, progress=False)
            ckpt = workspace.home() / "runs" / f"{study}-{tag}" / "checkpoints" / f"step-{step:09d}"
        for key in keys:
            if key not in judged:
                shift = r["shift"] if key[2] == "target" else "base"
                outcomes = scenes_outcomes(ckpt, shift, meta["reporting_seed"], meta["reporting_episodes"], workers)
                append_judged(path, key, outcomes)
                judged[key] = outcomes
                print(f"{tag} step {step} {key[2]}: {100 * sum(outcomes) / len(outcomes):.1f}%", flush=True)
    shutil.copyfile(path, records / JUDGED)


def base_checkpoint(plan) -> Path:
    from nsl.catalog import Catalog
    from nsl.services.refs import resolve_init

    with Catalog() as cat:
        return Path(resolve_init(cat, plan.base).path)


def scenes_outcomes(ckpt: Path, shift: str, seed: int, episodes: int, workers: int) -> list[bool]:
    """Per-scene success of a checkpoint on ``episodes`` test-object scenes of ``shift`` (``base``: none)."""
    from nsl.collectors import parse_shift_list
    from nsl.eval import EvalConfig, evaluate_outcomes
    from nsl.learners import load_policy

    (spec,) = parse_shift_list(shift)
    config = EvalConfig(episodes=episodes, seed=seed, workers=workers, batch=8)
    got = evaluate_outcomes(functools.partial(load_policy, str(ckpt)), [spec], config, progress=False)
    return list(next(iter(got.values())))


def curves(study: str, out: Path) -> None:
    """Copy the finished runs' curves and the plan's facts to ``out`` (no evaluation): the Fig. 5.7 part of the
    records, safe to commit while the study still runs."""
    from nsl import workspace
    from nsl.eval.records import read_curve

    meta = meta_of(plan_of(study))
    (out / "curves").mkdir(parents=True, exist_ok=True)
    done = 0
    for r in meta["runs"]:
        path = workspace.home() / "runs" / f"{study}-{r['tag']}" / "curve.csv"
        rows = read_curve(path) if path.is_file() else []
        if rows and rows[-1].step == meta["steps"]:
            shutil.copyfile(path, out / "curves" / f"{r['tag']}.csv")
            done += 1
    if not (out / "meta.json").is_file():
        (out / "meta.json").write_text(json.dumps(meta, indent=1) + "\n")
    print(f"{done} of {len(meta['runs'])} runs finished; their curves are in {out / 'curves'}")


def export(study: str, out: Path) -> None:
    from nsl import workspace

    src = workspace.home() / "studies" / study / "judging"
    if not (src / "meta.json").is_file():
        raise SystemExit(f"no judged records in {src}; run `evaluate {study}` first")
    shutil.copytree(src, out, dirs_exist_ok=True)
    print(f"copied {src} to {out}")


# --- report -------------------------------------------------------------------------------------------------------


def report(records: Path) -> None:
    from nsl.eval.selection import ORACLE, WHOLE_CURVE, score_criteria

    meta = json.loads((records / "meta.json").read_text())
    judged = read_judged(records / JUDGED)
    runs = judged_runs(records, meta, judged)
    labels = list(dict.fromkeys(r["label"] for r in meta["runs"]))
    print(f"{len(runs)} of {len(meta['runs'])} runs judged")
    plot(records, meta, labels)
    curve_means(records, meta, labels)
    plain = {x["shift"] for x in meta["runs"]}
    main = [r for r in runs if r.shift in plain]  # the five shifts at the plan's tier (label = shift)
    extra = [r for r in runs if r.shift not in plain]
    for title, judged_group in (("the five shifts at the plan's tier", main), ("the extra runs", extra)):
        by_label: dict[str, list] = {}
        for r in sorted(judged_group, key=lambda r: r.seed):
            by_label.setdefault(r.shift, []).append(r)
        if not by_label:
            continue
        n = min(len(v) for v in by_label.values())  # as many seeds on every shift
        group = [r for v in by_label.values() for r in v[:n]]
        print(f"\n### {title} ({n} seeds each)\n")
        print(
            "| criterion | shift | chosen steps | success at the pick | regret vs the oracle [95%] | "
            "Spearman's rho | base task at the pick |"
        )
        print("|---|---|---|---|---|---|---|")
        scores = score_criteria(group, meta["patience"], meta["fixed_step"])
        order = [ORACLE, "eval", WHOLE_CURVE, "softopc", "auc", "td", "qmean", "fqe", "fixed", "final"]
        for name in order:
            for s in scores:
                if s.criterion != name:
                    continue
                rho = "-" if s.rho is None else f"{s.rho:+.2f}"
                print(
                    f"| {name} | {s.shift or '**mean**'} | {' '.join(map(str, s.steps)) if s.shift else ''} | "
                    f"{100 * s.target.mean:.1f}% | {s.regret.points()} | {rho} | {100 * s.base.mean:.1f}% |"
                )
    refit_table(meta, judged, main)


def refit_table(meta: dict, judged: dict, runs: list) -> None:
    """Refit against the held-out pick, for every criterion whose refits are all scored."""
    from nsl.eval.selection import curve_picks, score_refit

    seed, n = meta["reporting_seed"], meta["reporting_episodes"]
    tags = {r.tag for r in runs}
    criteria = set()
    for t, *_rest in judged:
        for tag in tags:
            if t.startswith("refit-") and t.endswith("-" + tag):
                criteria.add(t[len("refit-") : -len(tag) - 1])
    for criterion in sorted(criteria):
        refits: dict[str, dict[str, list[bool]]] = {}
        for r in runs:
            pick = curve_picks(r.rows, meta["patience"], meta["fixed_step"])[criterion]
            for (tag, step, task, s, k), o in judged.items():  # a refit to another step count does not count
                if tag == refit_tag(criterion, r.tag) and step == pick and s == seed and k == n:
                    refits.setdefault(r.tag, {})[task] = o
        done = [r for r in runs if len(refits.get(r.tag, {})) == 2]
        by_shift: dict[str, list] = {}
        for r in sorted(done, key=lambda r: r.seed):
            by_shift.setdefault(r.shift, []).append(r)
        if not by_shift:
            continue
        k = min(len(v) for v in by_shift.values())
        group = [r for v in by_shift.values() for r in v[:k]]
        shifts = {r.shift for r in runs}
        print(f"\n### Refit at {criterion}'s step count, all target episodes ({k} seeds each)\n")
        if set(by_shift) != shifts:
            print(f"Refits finished on {len(by_shift)} of {len(shifts)} shifts: the mean is over those only.\n")
        print("| shift | steps | held-out run at the pick | refit | refit - pick [95%] | base task: refit - pick |")
        print("|---|---|---|---|---|---|")
        for x in score_refit(group, refits, criterion, meta["patience"], meta["fixed_step"]):
            steps = " ".join(map(str, x.steps)) if x.shift else ""
            print(
                f"| {x.shift or '**mean**'} | {steps} | {100 * x.pick.mean:.1f}% | {100 * x.refit.mean:.1f}% | "
                f"{x.gain.points()} | {x.base_gain.points()} |"
            )


def curve_means(records: Path, meta: dict, labels: list[str]) -> None:
    """The finished runs' seed means on the selection scenes, shift / base task: at step 0, at the shift's peak,
    at the recipe's step and at the last step."""
    from nsl.eval.records import read_curve

    print(f"\n| runs | seeds | step 0 | peak (step) | step {meta['fixed_step']} | step {meta['steps']} |")
    print("|---|---|---|---|---|---|")
    for label in labels:
        paths = [records / "curves" / f"{r['tag']}.csv" for r in meta["runs"] if r["label"] == label]
        curves = [{x.step: x for x in read_curve(p)} for p in paths if p.is_file()]
        if not curves:
            continue

        def at(step: int, curves: list = curves) -> str:
            t = sum(c[step].target.success_rate for c in curves) / len(curves)
            b = sum(c[step].base.success_rate for c in curves) / len(curves)
            return f"{100 * t:.1f} / {100 * b:.1f}"

        steps = sorted(set.intersection(*(set(c) for c in curves)))
        peak = max(steps, key=lambda s: (sum(c[s].target.success_rate for c in curves), -s))
        last = meta["steps"]
        print(f"| {label} | {len(curves)} | {at(0)} | {at(peak)} ({peak}) | {at(meta['fixed_step'])} | {at(last)} |")


def plot(records: Path, meta: dict, labels: list[str]) -> None:
    """Fig. 5.7: success on the shift and on the base task (selection scenes) against steps, a panel per run
    group, each seed a thin line and their mean a thick one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from nsl.eval.records import read_curve

    cols = min(4, len(labels))
    rows_n = (len(labels) + cols - 1) // cols
    fig, axes = plt.subplots(rows_n, cols, figsize=(4 * cols, 3.2 * rows_n), sharex=True, sharey=True, squeeze=False)
    for ax, label in zip(axes.flat, labels):
        for task, colour in (("target", "tab:blue"), ("base", "tab:grey")):
            curves = []
            for r in meta["runs"]:
                path = records / "curves" / f"{r['tag']}.csv"
                if r["label"] != label or not path.is_file():
                    continue
                rows = read_curve(path)
                xs = [x.step for x in rows]
                ys = [100 * (x.target if task == "target" else x.base).success_rate for x in rows]
                ax.plot(xs, ys, color=colour, alpha=0.3, lw=0.8)
                curves.append(dict(zip(xs, ys)))
            if curves:
                common = sorted(set.intersection(*(set(c) for c in curves)))
                ax.plot(
                    common,
                    [sum(c[s] for c in curves) / len(curves) for s in common],
                    color=colour,
                    lw=2,
                    label="shift" if task == "target" else "base task",
                )
        ax.axvline(meta["fixed_step"], color="k", ls=":", lw=0.8)
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("gradient steps")
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(labels) :]:
        ax.axis("off")
    axes[0][0].set_ylabel("success on 200 selection scenes (%)")
    handles = {h.get_label(): h for ax in axes.flat for h in ax.get_lines() if not h.get_label().startswith("_")}
    if handles:
        fig.legend(list(handles.values()), list(handles), loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(records / "curves.png", dpi=110)
    print(f"wrote {records / 'curves.png'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("evaluate", help="evaluate the finished runs' checkpoints and picks (resumable)")
    e.add_argument("study")
    e.add_argument("--workers", type=int, default=2)
    e.add_argument(
        "--episodes",
        type=int,
        nargs=2,
        default=(ORACLE_EPISODES, REPORTING_EPISODES),
        metavar=("ORACLE", "REPORTING"),
        help="scenes of each judging set (a smaller pair: a smoke run)",
    )
    e.add_argument("--only", nargs="*", default=[], metavar="TAG", help="judge these runs only")
    c = sub.add_parser("curves", help="copy the finished runs' curves out of the workspace (no evaluation)")
    c.add_argument("study")
    c.add_argument("--out", type=Path, required=True)
    f = sub.add_parser("refit", help="retrain each run on all its target data to a criterion's step count")
    f.add_argument("study")
    f.add_argument("--criterion", required=True, help="whose step count: softopc, auc, td, qmean, fqe, fixed, ...")
    f.add_argument("--workers", type=int, default=2)
    f.add_argument("--only", nargs="*", default=[], metavar="TAG", help="refit these runs only")
    x = sub.add_parser("export", help="copy the judged records out of the workspace")
    x.add_argument("study")
    x.add_argument("--out", type=Path, required=True)
    r = sub.add_parser("report", help="the criteria table and the curves, from the records")
    r.add_argument("records", type=Path)
    a = ap.parse_args()
    if a.cmd == "evaluate":
        evaluate(a.study, a.workers, tuple(a.episodes), a.only)
    elif a.cmd == "refit":
        refit(a.study, a.criterion, a.workers, a.only)
    elif a.cmd == "curves":
        curves(a.study, a.out)
    elif a.cmd == "export":
        export(a.study, a.out)
    else:
        report(a.records)


if __name__ == "__main__":
    main()
