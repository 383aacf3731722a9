"""Plugins: shifts, policies and learners that other packages add to nsl (docs/extending.md).

A package declares them as Python entry points, one per name::

    [project.entry-points."nsl.shifts"]
    occluder = "nsl_occluder:OCCLUDER"          # a nsl.collectors.ShiftDef

    [project.entry-points."nsl.policies"]
    sweep = "nsl_occluder:SweepPolicy"          # --policy nsl_occluder.sweep[:ARGS]

or, in a notebook, registers them with ``nsl.collectors.register_shift`` / ``register_policy``.

Whatever a plugin makes records the plugin's package and version (``{"package": ..., "version": ...}`` under the
key ``plugin``).  Reading it where that package is missing, or at another major version, fails in one line that
names the package (:func:`require`).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from functools import cache
from typing import Any

from nsl.errors import ConfigError, IncompatibleVersionError, UnknownReferenceError

GROUPS = ("nsl.shifts", "nsl.policies", "nsl.learners")
PLUGIN_KEY = "plugin"


@cache
def _entry_points(group: str) -> dict[str, Any]:
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=group)}


def names(group: str) -> list[str]:
    """The names installed packages declare in an entry-point group."""
    return sorted(_entry_points(group))


def load(group: str, name: str) -> tuple[Any, dict[str, str]] | None:
    """The object an installed package declares as ``name`` in ``group``, with its package and version; None if
    no package declares it.  A plugin that fails to import fails in one line naming its package."""
    ep = _entry_points(group).get(name)
    if ep is None:
        return None
    info = {
        "package": ep.dist.name if ep.dist else ep.module.split(".")[0],
        "version": ep.dist.version if ep.dist else "0",
    }
    try:
        return ep.load(), info
    except Exception as e:  # noqa: BLE001 - a broken plugin is the plugin's fault: say which one
        raise ConfigError(
            f"plugin {name!r} of package {info['package']} {info['version']} ({group}) failed to load "
            f"({type(e).__name__}: {e}); reinstall or fix that package"
        ) from None


def recorded(obj: Any) -> Iterator[dict[str, str]]:
    """Every plugin record (``{"package", "version"}`` under the key ``plugin``) in a JSON-like object."""
    if isinstance(obj, dict):
        p = obj.get(PLUGIN_KEY)
        if isinstance(p, dict) and "package" in p:
            yield p
        for v in obj.values():
            yield from recorded(v)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            yield from recorded(v)


def _major(version: str) -> str:
    return str(version).split(".")[0]


def require(records: Iterable[dict[str, str]], what: str) -> None:
    """Refuse, in one line naming the package, to read ``what`` when a plugin it records is not installed here
    or is installed at another major version."""
    from importlib.metadata import PackageNotFoundError, version

    for p in {(r["package"], str(r.get("version", ""))): r for r in records}.values():
        try:
            have = version(p["package"])
        except PackageNotFoundError:
            raise UnknownReferenceError(
                f"{what} was made with the plugin package {p['package']} {p.get('version', '')}, which is not "
                f"installed here; install it (pip install {p['package']}) to read it"
            ) from None
        if _major(have) != _major(p.get("version", "")):
            raise IncompatibleVersionError(
                f"{what} was made with the plugin package {p['package']} {p.get('version')}, but {have} is "
                f"installed; install {p['package']}=={_major(p.get('version', ''))}.* to read it"
            )
