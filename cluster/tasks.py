"""Ray task plumbing shared by the executor (units) and the chunk runner (collection chunks).

Both :mod:`.executor` and :mod:`.collect` import from here, so neither imports
the other back (the executor makes a ``RayChunkRunner``; the runner needs only
these two helpers).
"""

from __future__ import annotations

from typing import Any

from nsl.errors import EnvironmentSetupError, NslError


def get(ray, ref):
    """``ray.get`` that re-raises an nsl error from a task as itself (one line), not wrapped in a Ray error.

    A task that failed for good for the cluster's reasons (its node lost more often than ``max_retries``)
    becomes a one-line :class:`EnvironmentSetupError`; a bug in the task keeps its traceback.
    """
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as e:
        if isinstance(e.cause, NslError):
            raise e.cause from None
        raise
    except ray.exceptions.RayError as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        raise EnvironmentSetupError(
            f"the Ray cluster lost a task it could not run again ({type(e).__name__}: "
            f"{first}); run the same command again to resume"
        ) from e


_REMOTES: dict[Any, Any] = {}


def _remote(ray, fn):
    """``ray.remote(fn)``, made once per function (each call would export it again)."""
    if fn not in _REMOTES:
        _REMOTES[fn] = ray.remote(fn)
    return _REMOTES[fn]
