"""Every subcommand's options: help text on each, one spelling per idea, closed value sets as choices."""

from __future__ import annotations

import argparse

import pytest

from nsl.cli import build_parser
from nsl.commands import train
from nsl.commands._options import rename_old_options

# dest -> the one option string that may carry it
CANONICAL = {
    "batch_size": "--batch-size",
    "num_envs": "--num-envs",
    "workers": "--workers",
    "seed": "--seed",
    "json": "--json",
    "data": "--data",
    "checkpoint": "--checkpoint",
    "init": "--init",
}
# spellings of those ideas that must not come back as visible options
FORBIDDEN = {
    "--batch",
    "--bs",
    "--num-workers",
    "--jobs",
    "-j",
    "--procs",
    "--random-seed",
    "--dataset",
    "--datasets",
    "--ckpt",
    "--model",
    "--parent",
    "--json-lines",
    "--jsonl",
}
# ideas whose destination must use the canonical word
WORDS = {"batch": "batch_size", "worker": "workers", "seed": "seed", "json": "json"}
CLOSED = {
    "split": {"train", "test"},
    "criterion": {"eval", "softopc", "auc", "td", "qmean", "fqe"},
    "precision": {"fp32", "bf16", "auto"},
    "engine": {"mujoco", "pybullet"},
    "device": {"cpu", "cuda", "auto"},
}


def _walk(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _walk(sub, (*path, name))


PARSERS = list(_walk(build_parser()))


def _visible(parser):
    return [
        a
        for a in parser._actions
        if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction, argparse._VersionAction))
        and a.help != argparse.SUPPRESS
    ]


def test_the_walk_reaches_every_command():
    names = {" ".join(p) for p, _ in PARSERS}
    assert {
        "collect",
        "train",
        "eval",
        "continual",
        "render",
        "report",
        "dataset ls",
        "catalog ls",
        "bench learner",
    } <= names


@pytest.mark.parametrize("path, parser", PARSERS, ids=[" ".join(p) or "nsl" for p, _ in PARSERS])
def test_options_have_help_and_canonical_names(path, parser):
    for a in _visible(parser):
        label = f"nsl {' '.join(path)} {'/'.join(a.option_strings) or a.dest}"
        assert a.help and a.help.strip(), f"{label} has no help text"
        assert not FORBIDDEN & set(a.option_strings), f"{label} uses a retired spelling"
        if a.dest in CANONICAL and a.option_strings:
            assert a.option_strings == [CANONICAL[a.dest]], label
        for word, dest in WORDS.items():
            if word in a.dest and a.option_strings:
                assert a.dest == dest, f"{label}: write {CANONICAL[dest]} for this idea"
        if a.dest == "json":
            assert isinstance(a, argparse._StoreTrueAction), label
        if a.dest in CLOSED:
            assert set(a.choices or ()) == CLOSED[a.dest], f"{label} should list its values as choices"
    hidden = [a.dest for a in parser._actions if a.help == argparse.SUPPRESS and a.option_strings]
    assert hidden in ([], ["stop_after_files"])  # a test hook; nothing else is undocumented


def test_closed_sets_match_the_libraries():
    from nsl.eval import CRITERIA
    from nsl.learners import METHODS

    assert set(train.METHODS) == set(METHODS) and set(train.CRITERIA) == set(CRITERIA)
    from nsl.learners.precision import PRECISIONS
    from nsl.services.options import PRECISIONS as OPTION_PRECISIONS

    assert OPTION_PRECISIONS == PRECISIONS
    from nsl.learners.device import DEVICES
    from nsl.services.options import DEVICES as OPTION_DEVICES

    assert OPTION_DEVICES == DEVICES
    from nsl.collectors import ENGINES
    from nsl.services.options import ENGINES as OPTION_ENGINES

    assert OPTION_ENGINES == ENGINES


CONFIGURED = [(p, parser) for p, parser in PARSERS if parser.get_default("config") is not None]


def test_the_commands_that_run_an_action_name_its_config():
    assert {" ".join(p) for p, _ in CONFIGURED} >= {"collect", "train", "eval", "continual", "efficiency"}


@pytest.mark.parametrize("path, parser", CONFIGURED, ids=[" ".join(p) for p, _ in CONFIGURED])
def test_no_option_default_disagrees_with_its_config(path, parser):
    """Every option that fills a config field defaults to the field's default and says the field's help."""
    from dataclasses import MISSING, fields

    config = parser.get_default("config")
    by_name = {f.name: f for f in fields(config)}
    checked = 0
    for a in _visible(parser):
        f = by_name.get(a.dest)
        if f is None:
            continue
        checked += 1
        label = f"nsl {' '.join(path)} {'/'.join(a.option_strings)}"
        if a.required or isinstance(a, argparse._AppendAction):
            assert a.default is None, f"{label}: a required or repeated option has no default of its own"
        else:
            assert f.default is not MISSING and a.default == f.default, (
                f"{label} defaults to {a.default!r}, {config.__name__}.{f.name} to {f.default!r}"
            )
        assert a.help.replace("%%", "%") == f.metadata["help"], f"{label}: help differs from {config.__name__}'s"
    assert checked >= len(by_name) - 1, f"nsl {' '.join(path)} fills few fields of {config.__name__}"


def test_changing_a_config_default_changes_the_help(monkeypatch, capsys):
    from nsl.services.options import EvaluateOptions, TrainOptions

    monkeypatch.setattr(TrainOptions.__dataclass_fields__["batch_size"], "default", 96)
    monkeypatch.setattr(EvaluateOptions.__dataclass_fields__["seed"], "default", 4242)
    for argv, text in ((["train", "--help"], "(default: 96)"), (["eval", "--help"], "(default: 4242)")):
        with pytest.raises(SystemExit):
            build_parser().parse_args(argv)
        out = capsys.readouterr().out
        assert text in " ".join(out.split()), argv


def test_the_scene_seeds_are_named_and_distinct():
    import nsl
    from nsl.eval import EarlyStopConfig, EvalConfig

    seeds = (nsl.EVAL_SCENES, nsl.SELECTION_SCENES, nsl.REPORTING_SCENES, nsl.FINAL_REPORTING_SCENES)
    assert len(set(seeds)) == 4
    assert EarlyStopConfig().seed == nsl.SELECTION_SCENES and EvalConfig().seed == nsl.EVAL_SCENES
    assert build_parser().parse_args(["train", "--data", "d", "--name", "n"]).eval_scenes == nsl.SELECTION_SCENES


def test_renamed_options_still_work_and_say_the_new_name(capsys):
    parser = build_parser()
    args = parser.parse_args(
        rename_old_options(
            ["collect", "--shift", "base", "--episodes", "2", "--policy", "random", "--dataset", "d", "--batch=4"]
        )
    )
    assert args.data == "d" and args.num_envs == 4
    err = capsys.readouterr().err
    assert "--dataset is now --data" in err and "--batch is now --num-envs in nsl collect" in err
    assert parser.parse_args(["eval"]).num_envs == 8
    args = parser.parse_args(rename_old_options(["train", "--data", "d", "--name", "n", "--batch=16"]))
    assert args.batch_size == 16 and "--batch is now --batch-size;" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["collect", "eval", "online"])
def test_num_envs_and_the_old_batch_size_with_its_note(command, capsys):
    """Environments per worker are --num-envs; --batch-size keeps working there for one release, with a note."""
    required = {
        "collect": ["--shift", "base", "--episodes", "2", "--policy", "random", "--data", "d"],
        "eval": [],
        "online": ["--shift", "base"],
    }[command]
    parser = build_parser()
    assert parser.parse_args([command, *required, "--num-envs", "3"]).num_envs == 3
    assert capsys.readouterr().err == ""
    for old in (["--batch-size", "5"], ["--batch-size=5"]):
        assert parser.parse_args(rename_old_options([command, *required, *old])).num_envs == 5
        err = capsys.readouterr().err
        assert err == f"nsl: --batch-size is now --num-envs in nsl {command}; the old name will go away\n"
    # train keeps --batch-size (transitions per gradient step), with no note
    args = parser.parse_args(rename_old_options(["train", "--data", "d", "--name", "n", "--batch-size", "16"]))
    assert args.batch_size == 16 and capsys.readouterr().err == ""


def test_the_python_api_takes_num_envs_and_the_old_batch_size_with_a_warning():
    import nsl
    from nsl.api import _settle

    assert _settle(nsl.EvaluateOptions, None, {"num_envs": 2}, "evaluate").num_envs == 2
    with pytest.warns(FutureWarning, match=r"nsl.evaluate\(batch_size=...\) is now num_envs="):
        assert _settle(nsl.EvaluateOptions, None, {"batch_size": 3}, "evaluate").num_envs == 3
    assert _settle(nsl.TrainOptions, None, {"batch_size": 32, "data": ("d",)}, "train").batch_size == 32


def test_help_shows_defaults(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["eval", "--help"])
    out = capsys.readouterr().out
    assert "(default: 1000)" in out and "(default: 8)" in out and "--num-envs" in out
