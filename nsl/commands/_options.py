"""The options every command spells the same way, and the help style they share.

One name per idea across all commands (``tests/test_cli_options.py`` checks it):

* ``--data``: dataset references (``NAME[@vN][:K]``), or the name a collection writes;
* ``--checkpoint``: a checkpoint to use as it is; ``--init``: the parent a run starts from;
* ``--batch-size``: how many items one batched call handles (transitions, frames);
* ``--num-envs``: environments per worker stepping in lock-step (collect, eval, online; Gymnasium's ``num_envs``);
* ``--workers``: worker processes; ``--seed``: the seed; ``--json``: one JSON document on stdout, nothing else.

Help texts show their defaults through :class:`HelpFormatter`.  Options that
were renamed keep working under their old spelling (:data:`RENAMED`), with a note.
"""

from __future__ import annotations

import argparse
import sys


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps descriptions as written and adds "(default: X)" where the help does not already say it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (
            "default" in text
            or default is None
            or default is False
            or default == []
            or default == argparse.SUPPRESS
            or not action.option_strings
        ):
            return text
        return super()._get_help_string(action)


def add_parser(sub: argparse._SubParsersAction, name: str, **kwargs) -> argparse.ArgumentParser:
    """A subcommand parser in the shared help style."""
    return sub.add_parser(name, formatter_class=HelpFormatter, **kwargs)


# Old spellings still accepted (nsl.cli.main rewrites them and says the new name on stderr).
RENAMED = {"--dataset": "--data", "--batch": "--batch-size"}
# ... and those retired in some commands only: environments per worker were --batch-size in nsl 0.1.
RENAMED_IN = {
    command: {"--batch-size": "--num-envs", "--batch": "--num-envs"} for command in ("collect", "eval", "online")
}


def rename_old_options(argv: list[str]) -> list[str]:
    """``argv`` with retired option spellings replaced by the current ones (a note for each on stderr)."""
    command = next((a for a in argv if not a.startswith("-")), "")
    renamed = {**RENAMED, **RENAMED_IN.get(command, {})}
    out = []
    for arg in argv:
        name, eq, value = arg.partition("=")
        if name in renamed:
            where = f" in nsl {command}" if name in RENAMED_IN.get(command, {}) else ""
            print(f"nsl: {name} is now {renamed[name]}{where}; the old name will go away", file=sys.stderr)
            arg = renamed[name] + eq + value
        out.append(arg)
    return out


def add_json(p: argparse.ArgumentParser, what: str = "the result") -> None:
    p.add_argument("--json", action="store_true", help=f"print {what} as one JSON document on stdout, nothing else")


def add_wait(p, what: str) -> None:
    """``--wait``: queue behind another process that is writing the same thing instead of failing (nsl.locks)."""
    p.add_argument(
        "--wait",
        action="store_true",
        help=f"if another process is writing this {what}, wait for it to finish instead of failing at once "
        "(one writer at a time; the refusal names the other process)",
    )


def add_workers(p, help: str = "worker processes (the results do not depend on it)") -> None:
    p.add_argument("--workers", type=int, default=1, help=help)


def add_seed(p, default: int = 0, help: str = "seed") -> None:
    p.add_argument("--seed", type=int, default=default, help=help)


def add_field(p, config: type, name: str, *flags: str, **overrides) -> argparse.Action:
    """An option whose default, help text, choices and metavar come from field ``name`` of dataclass ``config``.

    The config is the one source of the default (``nsl.services.options``); ``overrides`` add argparse keywords
    (``type``, ``required``, ``action``, ...).  A bool field becomes a ``store_true`` flag.
    """
    from dataclasses import MISSING, fields

    field = next((f for f in fields(config) if f.name == name), None)
    if field is None:
        raise AttributeError(f"{config.__name__} has no field {name!r}")
    meta = dict(field.metadata)
    kwargs = {"dest": name, "help": (meta.get("help") or "").replace("%", "%%") or None}
    default = field.default if field.default is not MISSING else None
    if "choices" in meta:
        kwargs["choices"] = meta["choices"]
    if "metavar" in meta:
        kwargs["metavar"] = meta["metavar"]
    if isinstance(default, bool):
        kwargs["action"] = "store_true"
    elif "action" not in overrides:
        kind = overrides.pop("type", None) or _type_of(field.type, default)
        if kind is not None:
            kwargs["type"] = kind
    kwargs["default"] = default
    kwargs.update(overrides)
    if kwargs.get("required") or kwargs.get("action") == "append":
        kwargs["default"] = None  # a list option starts empty; the caller turns it into the field's tuple
    return p.add_argument(*(flags or ("--" + name.replace("_", "-"),)), **kwargs)


def _type_of(annotation, default):
    """The argparse type of a field: from its default's type, else from its annotation's first name."""
    if isinstance(default, (int, float, str)) and not isinstance(default, bool):
        return type(default)
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    for name, kind in (("int", int), ("float", float), ("str", str)):
        if text.split("|")[0].strip() == name:
            return kind
    return None
