"""Where learners are found by name: the built-in ``qtopt`` and ``iql``, those registered in this process with
:func:`register_learner` (a notebook), then the ``nsl.learners`` entry points of installed packages."""

from __future__ import annotations

from typing import Any

from nsl.errors import ConfigError, unknown

from .algorithm import Algorithm

BUILT_IN = ("qtopt", "iql")

_REGISTERED: dict[str, tuple[Algorithm, dict[str, str] | None]] = {}


def register_learner(algo: Algorithm, plugin: dict[str, str] | None = None) -> None:
    """Make ``algo`` available as ``--learner algo.name`` in this process (a notebook's plugin); ``plugin`` is
    the package and version its checkpoints record (default: ``__main__``)."""
    if not isinstance(algo, Algorithm) or not algo.name:
        raise ConfigError(f"register_learner takes an nsl.learners.Algorithm with a name, not {algo!r}")
    if algo.name in BUILT_IN:
        raise ConfigError(f"learner {algo.name!r} is built in; give yours another name (e.g. mypkg.{algo.name})")
    _REGISTERED[algo.name] = (algo, plugin or {"package": "__main__", "version": "0"})


def learner_names() -> list[str]:
    """Every learner name: the built-in ones, then those registered here or installed as plugins."""
    from nsl import plugins

    return [*BUILT_IN, *sorted(set(_REGISTERED) | set(plugins.names("nsl.learners")))]


def find_learner(name: str) -> tuple[Algorithm, dict[str, str] | None]:
    """The algorithm called ``name`` and, for a plugin's, its package and version (None for a built-in one)."""
    if name == "qtopt":
        from .qtopt import QTOpt

        return QTOpt(), None
    if name == "iql":
        from .iql import IQL

        return IQL(), None
    if name not in _REGISTERED:
        from nsl import plugins

        found = plugins.load("nsl.learners", name)
        if found is None:
            raise unknown(
                "learner", name, learner_names(), "a plugin learner comes from an installed package's nsl.learners"
            )
        obj, info = found
        algo = obj() if isinstance(obj, type) else obj
        if not isinstance(algo, Algorithm):
            raise ConfigError(
                f"plugin learner {name!r} of package {info['package']} is not an nsl.learners.Algorithm; "
                "fix that package"
            )
        _REGISTERED[name] = (algo, info)
    return _REGISTERED[name]


def parse_learner(spec: str) -> tuple[str, dict[str, Any]]:
    """``"iql:expectile=0.9,v_warmup=100"`` -> ``("iql", {"expectile": 0.9, "v_warmup": 100})``."""
    name, _, rest = spec.partition(":")
    if not name:
        raise ConfigError(f"--learner {spec!r}: write NAME or NAME:KEY=VALUE,..., e.g. iql:expectile=0.9")
    options: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"--learner {spec!r}: option {item!r} is not KEY=VALUE, e.g. iql:expectile=0.9")
        options[key] = _number(value)
    return name, options


def _number(value: str) -> Any:
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value
