"""Where nsl's work runs: local processes (the default) or a Ray cluster.

``--cluster`` (or ``$NSL_CLUSTER``) takes one of:

* ``local``: local processes, as without this module (the default);
* ``ray``: the cluster named in ``$RAY_ADDRESS``, else a Ray instance started
  on this machine for the command and shut down after it (listening on
  127.0.0.1 only);
* ``auto`` or ``ray://HOST:PORT``: an existing cluster (``ray start`` or the
  cluster launcher), left running afterwards.

An :class:`Executor` gives two things to the code that runs work:

* ``runner``: ``None`` locally, else a chunk runner for
  ``nsl.collectors.collect_episodes(..., runner=...)`` (see :mod:`.collect`);
* ``submit(unit)`` / ``wait()`` / ``run_units(units)``: independent callables
  (:class:`Unit`) run as Ray tasks that each hold ``num_cpus`` CPUs, results
  returned in completion order.  Locally they run one after another in this
  process.

Ray is imported only when a Ray executor is made, and connects on first use,
so ``--cluster ray`` costs nothing when a command has nothing to do.  An
executor shuts down only the Ray instance it started (never ``ray stop``).
"""

from __future__ import annotations

import importlib
import os
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nsl.errors import ConfigError, EnvironmentSetupError, NslError

from .tasks import _remote, get

CLUSTER_ENV = "NSL_CLUSTER"
INSTALL_HINT = "install it with `pip install 'nsl[ray]'` (in a checkout: `pip install -e '.[ray]'`)"
LOOPBACK_ENV = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"  # "0": a Ray instance started here binds 127.0.0.1 only
MARKER_DIR = ".cluster"  # under NSL_HOME: a file per driver, proving to a task that it sees the same NSL_HOME
STORE_CACHE_ENV = "NSL_STORE_CACHE"  # with --store: where nodes keep their own NSL_HOME (default ~/.cache/nsl/store)


def parse_cluster(value: str | None) -> str:
    """The cluster spec from ``--cluster``, else ``$NSL_CLUSTER``, else ``local``; checked."""
    spec = (value or os.environ.get(CLUSTER_ENV) or "local").strip()
    if spec in ("local", "ray", "auto") or (spec.startswith("ray://") and len(spec) > len("ray://")):
        return spec
    where = "--cluster" if value else f"${CLUSTER_ENV}"
    raise ConfigError(f"{where} {spec!r} is not a cluster; use local, ray, auto or ray://HOST:PORT")


def add_option(parser, help: str | None = None) -> None:
    """Add ``--cluster`` to a subcommand's parser."""
    parser.add_argument(
        "--cluster",
        default=None,
        metavar="local|ray|auto|ray://HOST:PORT",
        help=help
        or f"where simulators run: local processes (default, or ${CLUSTER_ENV}), Ray on this "
        "machine or at $RAY_ADDRESS (ray), or an existing Ray cluster (auto, ray://...); "
        "results are identical; see docs/scale.md",
    )


def import_ray(spec: str = "ray"):
    """The ``ray`` module, or a one-line error saying how to install it."""
    try:
        return importlib.import_module("ray")
    except ImportError:
        raise EnvironmentSetupError(f"--cluster {spec} needs Ray, which is not installed; {INSTALL_HINT}") from None


@dataclass(frozen=True)
class Unit:
    """An independent piece of work: ``fn(*args, **kwargs)`` holding ``num_cpus`` CPUs.

    ``fn`` and its arguments must be picklable (module-level functions,
    ``functools.partial``); the result should be small (a summary: files go to
    the shared ``NSL_HOME``, see docs/scale.md).
    """

    key: str  # a unique name, returned with the result
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict[str, Any] = field(default_factory=dict)
    num_cpus: float = 1.0  # CPUs the unit holds while it runs (its torch threads)
    num_gpus: float = 0.0  # GPUs it holds (Ray sets CUDA_VISIBLE_DEVICES; a unit without one sees none)


class UnitFailed(NslError):
    """A unit raised; ``key`` names it, ``__cause__`` is its exception."""

    def __init__(self, key: str, error: BaseException):
        text = str(error) if isinstance(error, NslError) else f"{type(error).__name__}: {error}"
        super().__init__(f"unit {key} failed: {text.splitlines()[0] if text else type(error).__name__}")
        self.key = key
        self.error = error  # the unit's own exception (unwrapped from Ray's)


class Executor:
    """Local processes: no chunk runner; units run one at a time in this process."""

    name = "local"
    runner = None

    def __init__(self) -> None:
        self._queue: deque[Unit] = deque()

    def submit(self, unit: Unit) -> None:
        self._queue.append(unit)

    @property
    def outstanding(self) -> int:
        return len(self._queue)

    def wait(self) -> tuple[str, Any]:
        """The next finished unit's ``(key, result)``; raises :class:`UnitFailed` if it raised."""
        unit = self._queue.popleft()
        try:
            return unit.key, unit.fn(*unit.args, **unit.kwargs)
        except Exception as e:
            raise UnitFailed(unit.key, e) from e

    def run_units(self, units: Iterable[Unit]) -> Iterator[tuple[str, Any]]:
        """Submit every unit, then yield ``(key, result)`` as each finishes."""
        for unit in units:
            self.submit(unit)
        while self.outstanding:
            yield self.wait()

    def describe(self) -> dict[str, Any]:
        return {"cluster": self.name}

    def close(self) -> None:
        self._queue.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class RayExecutor(Executor):
    """A Ray cluster: chunks and units become Ray tasks, retried elsewhere when a node is lost."""

    def __init__(
        self,
        spec: str = "ray",
        init_kwargs: dict[str, Any] | None = None,
        max_retries: int = 5,
        store: str | None = None,
    ):
        super().__init__()
        self.name = spec
        self.store = store  # a URL: nodes keep their own NSL_HOME (node_home), units move folders via nsl.share.store
        if spec == "ray":
            self.address = os.environ.get("RAY_ADDRESS") or None  # None: start an instance here
        else:
            self.address = spec
        if self.address is None:
            os.environ.setdefault(LOOPBACK_ENV, "0")  # read when Ray is imported: listeners on 127.0.0.1
        self.ray = import_ray(spec)
        self.init_kwargs = dict(init_kwargs or {})  # ray.init options for an instance started here (num_cpus, ...)
        self.max_retries = max_retries  # a chunk or unit lost with its node is run again up to this often
        self._started = False  # True once this executor called ray.init (so close() calls ray.shutdown)
        self._pending: dict[Any, str] = {}  # unit task ref -> key
        self._marker: Path | None = None
        from nsl.version import code_version

        self.code_version = code_version()  # every task must run the same nsl (checked on its node)
        from .collect import RayChunkRunner

        self.runner = RayChunkRunner(self)

    def connect(self):
        """Connect (or start Ray here) on first use; returns the ``ray`` module."""
        ray = self.ray
        if ray.is_initialized():
            return ray
        import logging

        if self.address is None:
            # Ray runs workers at niceness 15 by default: on a busy machine they would lose the CPU to every other
            # process, where local worker processes run at the caller's priority.
            kwargs = {
                "include_dashboard": False,
                "logging_level": logging.WARNING,
                "_system_config": {"worker_niceness": 0},
                **self.init_kwargs,
            }
            ray.init(address="local", **kwargs)
        else:
            try:
                ray.init(address=self.address, logging_level=logging.WARNING)
            except ConnectionError as e:
                raise EnvironmentSetupError(
                    f"--cluster {self.name}: cannot reach a Ray cluster at {self.address} "
                    f"({str(e).splitlines()[0]}); start one with `ray start --head` "
                    "(docs/scale.md)"
                ) from None
        self._started = True
        return ray

    def cpus(self) -> int:
        """CPUs in the cluster now."""
        return max(1, int(self.connect().cluster_resources().get("CPU", 1)))

    def gpus(self) -> float:
        """GPUs in the cluster now."""
        return float(self.connect().cluster_resources().get("GPU", 0))

    def describe(self) -> dict[str, Any]:
        ray = self.connect()
        nodes = [n for n in ray.nodes() if n.get("Alive")]
        return {"cluster": self.name, "nodes": len(nodes), "cpus": self.cpus(), "ray": ray.__version__}

    def submit(self, unit: Unit) -> None:
        ray = self.connect()
        if unit.num_gpus and self.gpus() < unit.num_gpus:  # it would wait for a node that never comes
            raise ConfigError(
                f"unit {unit.key} asks for {unit.num_gpus:g} GPU(s) but the cluster has {self.gpus():g}; add a node "
                "with a GPU (ray start --num-gpus N) or drop --unit-gpus"
            )
        task = _remote(ray, _call_unit)
        ref = task.options(
            num_cpus=unit.num_cpus,
            num_gpus=unit.num_gpus,
            max_retries=self.max_retries,
            retry_exceptions=False,
            name=f"nsl-unit:{unit.key}",
        ).remote(
            unit.fn,
            unit.args,
            unit.kwargs,
            None if self.store else str(self._shared_marker()),
            unit.num_cpus,
            self.code_version,
            self.store,
        )
        self._pending[ref] = unit.key

    @property
    def outstanding(self) -> int:
        return len(self._pending)

    def wait(self) -> tuple[str, Any]:
        ray = self.connect()
        (ref,), _ = ray.wait(list(self._pending), num_returns=1)
        key = self._pending.pop(ref)
        try:
            return key, get(ray, ref)
        except NslError as e:
            raise UnitFailed(key, e) from e
        except ray.exceptions.RayTaskError as e:
            raise UnitFailed(key, e.cause if e.cause is not None else e) from e

    def _shared_marker(self) -> Path:
        """A file under this driver's NSL_HOME that every task must see (the shared-NSL_HOME check)."""
        if self._marker is None:
            from nsl.workspace import atomic_write_bytes, home

            self._marker = home().resolve() / MARKER_DIR / f"driver-{os.getpid()}-{uuid.uuid4().hex[:12]}"
            atomic_write_bytes(self._marker, b"")
        return self._marker

    def close(self) -> None:
        ray = self.ray
        if self._pending and ray.is_initialized():
            for ref in self._pending:
                ray.cancel(ref, force=True)
        self._pending.clear()
        if self._marker is not None:
            self._marker.unlink(missing_ok=True)
            self._marker = None
        if self._started:
            ray.shutdown()  # a Ray instance started here stops; a connection to a cluster is closed
            self._started = False


def open_executor(value: str | None = None, store: str | None = None, **init_kwargs) -> Executor:
    """The executor for ``--cluster VALUE`` (else ``$NSL_CLUSTER``, else local); use it as a context manager.

    ``store`` (a URL, :mod:`nsl.share.store`): the nodes share no ``NSL_HOME``; each unit runs in its node's own
    (:func:`node_home`).
    """
    spec = parse_cluster(value)
    if spec == "local":
        if store:
            raise ConfigError(
                f"--store {store} moves folders between cluster nodes; give --cluster too (local units share "
                "this machine's NSL_HOME)"
            )
        return Executor()
    return RayExecutor(spec, init_kwargs, store=store)


def node_home(store: str, node: str) -> Path:
    """The ``NSL_HOME`` a node keeps for the store URL ``store`` (``--store``, :mod:`nsl.share.store`): its cache
    of pulled folders and its units' outputs."""
    import hashlib

    base = Path(os.environ.get(STORE_CACHE_ENV) or Path.home() / ".cache" / "nsl" / "store").expanduser()
    return base / hashlib.sha256(store.encode()).hexdigest()[:12] / node


def _call_unit(
    fn,
    args: tuple,
    kwargs: dict,
    marker: str | None,
    num_cpus: float,
    driver_version: str | None = None,
    store: str | None = None,
):
    """A unit inside a Ray task: check the nsl version and the shared workspace (or, with a store, use the node's
    own), point NSL_HOME at it, run with its CPUs' threads."""
    import socket
    import sys

    from nsl.version import code_version

    if driver_version is not None and code_version() != driver_version:
        raise EnvironmentSetupError(
            f"node {socket.gethostname()} runs nsl {code_version()}, but the driver runs {driver_version}; install "
            "the same nsl on every node (docs/scale.md)"
        )
    if store is not None:
        import ray

        home = node_home(store, ray.get_runtime_context().get_node_id()[:12])
        home.mkdir(parents=True, exist_ok=True)
        os.environ["NSL_HOME"] = str(home)
    else:
        path = Path(str(marker))
        if not path.is_file():
            raise EnvironmentSetupError(
                f"NSL_HOME {path.parent.parent} of the driver is not visible on node {socket.gethostname()}; mount "
                "the same shared folder at that path on every node, or give --store URL (docs/scale.md)"
            )
        os.environ["NSL_HOME"] = str(path.parent.parent)
    torch = sys.modules.get("torch")
    if torch is not None:  # Ray gives a worker one thread; a unit gets one per CPU it holds
        torch.set_num_threads(max(1, int(num_cpus)))
    return fn(*args, **kwargs)
