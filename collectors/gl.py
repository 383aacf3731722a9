"""The OpenGL backend, chosen before anything imports MuJoCo.

MuJoCo reads ``MUJOCO_GL`` once, when ``mujoco`` is first imported, and
:mod:`.shifts` and :mod:`.scene` import it at module level.  The package's
``__init__`` calls :func:`choose_backend` first, so every nsl path to MuJoCo
(``nsl render``, collection, evaluation, training with evaluation) renders
headless in a plain shell.  No MuJoCo or GL library is loaded here.
"""

from __future__ import annotations

import os

DEFAULT_BACKEND = "egl"  # as the Makefile sets


def choose_backend() -> str:
    """Set ``MUJOCO_GL`` to ``egl`` unless the user set it (an empty value counts as unset); returns it."""
    if not os.environ.get("MUJOCO_GL"):
        os.environ["MUJOCO_GL"] = DEFAULT_BACKEND
    backend = os.environ["MUJOCO_GL"].lower()
    if backend == "egl":
        os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    return backend
