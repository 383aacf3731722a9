"""Imported once by the fork server that starts collection workers.

Workers fork from a process that already imported MuJoCo and parsed every
object mesh, so a new worker starts in milliseconds instead of re-importing
and re-parsing (no GL context exists before the fork; each worker makes its own).
"""

from . import sim_mujoco  # noqa: F401  (imports mujoco with MUJOCO_GL set)
from .objects import SPLITS, load_mesh, object_ids

for _split in SPLITS:
    for _i in object_ids(_split):
        load_mesh(_i)
