"""An example nsl plugin package (docs/extending.md).

* ``lens_occluder``: a shift.  A dark strip sticks to the wrist camera's housing, between the lens and the bin,
  and hides a band right of the picture's centre, 0.5 cm wide per unit severity (at most 2).
* ``nsl_occluder.centre[:NOISE]``: a scripted collection policy.  It descends at the bin's centre region with a
  random wrist position and yaw (Gaussian ``NOISE`` on each action, default 0.3), a weak but non-trivial
  baseline between ``random`` and ``oracle``.

nsl finds both through the entry points in ``pyproject.toml``; nothing in nsl's source names them.
"""

from __future__ import annotations

import numpy as np

from nsl.collectors import ShiftDef

__version__ = "0.1.0"

CAMERA_POS = np.array([0.0, -0.085, -0.05])  # nsl's wrist camera, in the wrist frame (collectors/scene.py)
CAMERA_TARGET = np.array([0.0, 0.0, -0.13])


def _params(severity: float) -> dict[str, float]:
    return {"width_cm": 0.5 * severity, "distance_cm": 2.0}


def _apply(spec, p: dict[str, float]) -> None:
    """A thin dark plate on the wrist body, ``distance_cm`` in front of the lens, covering its right side."""
    if p["width_cm"] <= 0:
        return
    view = (CAMERA_TARGET - CAMERA_POS) / np.linalg.norm(CAMERA_TARGET - CAMERA_POS)
    centre = CAMERA_POS + view * p["distance_cm"] / 100.0
    half = p["width_cm"] / 200.0
    centre[0] += 0.012 - half  # flush with the right edge of the view
    spec.body("wrist").add_geom(
        name="lens_occluder",
        type=6,  # mjGEOM_BOX
        size=[half, 0.0005, 0.012],
        pos=centre.tolist(),
        rgba=[0.05, 0.05, 0.05, 1.0],
        contype=0,
        conaffinity=0,
        mass=0.0001,
    )


LENS_OCCLUDER = ShiftDef(
    name="lens_occluder",
    kind="sensor",
    max_severity=2.0,
    params=_params,
    apply=_apply,
    doc="a dark strip on the wrist camera's housing hides a band of the picture (0.5 cm per unit severity)",
)


class CentrePolicy:
    """Descend near the bin's centre with a random offset and yaw; ``noise`` on every action component."""

    name = "nsl_occluder.centre"
    needs_privileged = False

    def __init__(self, noise: float = 0.3):
        if not 0.0 <= noise <= 2.0:
            raise ValueError(f"nsl_occluder.centre: noise {noise} is out of range; use 0..2")
        self.noise = noise

    def __call__(self, obs, *, rngs, privileged=None):
        out = np.zeros((len(rngs), 6), dtype=np.float32)
        for i, rng in enumerate(rngs):
            a = rng.normal(0.0, self.noise, 6)
            a[4] = -1.0  # keep the jaw open; auto-descent grasps at the bottom
            a[5] = -1.0
            out[i] = np.clip(a, -1.0, 1.0)
        return out

    def describe(self) -> dict:
        return {"noise": self.noise}


def centre_policy(args: str, *, control: str, move_step: float, yaw_step: float) -> CentrePolicy:
    """nsl's policy-plugin contract: ``factory(ARGS, *, control, move_step, yaw_step)`` -> a policy."""
    return CentrePolicy(float(args) if args else 0.3)
