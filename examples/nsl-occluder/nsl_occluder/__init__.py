"""An example nsl plugin package (docs/extending.md).

* ``lens_occluder``: a shift.  A dark strip sticks to the wrist camera's housing, between the lens and the bin,
  and hides a band right of the picture's centre, 0.5 cm wide per unit severity (at most 2).
* ``nsl_occluder.centre[:NOISE]``: a scripted collection policy.  It descends at the bin's centre region with a
  random wrist position and yaw (Gaussian ``NOISE`` on each action, default 0.3), a weak but non-trivial
  baseline between ``random`` and ``oracle``.
* ``nsl_occluder.bandit``: an offline learner.  It fits Q to each transition's own reward, with no bootstrapping
  (a contextual bandit: the grasp's last step is all it learns), and acts through nsl's CEM like QT-Opt.

nsl finds all three through the entry points in ``pyproject.toml``; nothing in nsl's source names them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nsl.collectors import ShiftDef
from nsl.learners import Algorithm

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


@dataclass(frozen=True)
class BanditOptions:
    """``--learner nsl_occluder.bandit:reward_scale=0.9``."""

    reward_scale: float = 1.0  # the target is reward_scale * r

    def __post_init__(self) -> None:
        if not 0.0 < self.reward_scale <= 1.0:
            raise ValueError(f"reward_scale {self.reward_scale} must be in (0, 1]")


class BanditLearner(Algorithm):
    """Q(s, a) fitted to the transition's reward by log loss; QT-Opt's optimiser, no target networks."""

    name = "nsl_occluder.bandit"
    methods = ("scratch", "ft", "new_head")  # nsl refuses pnn and ft_pnn for this learner
    Options = BanditOptions

    def create(self, net, lr, cfg, options):
        from nsl.learners import Learner

        return Learner.create(net, lr, cfg)  # its online network, Adam and generator will do

    def update(self, state, batch, cfg, step, options):
        import torch.nn.functional as F

        from nsl import keys
        from nsl.learners.augment import prepare_images
        from nsl.learners.cem import active_actions

        net = state.online
        image = prepare_images(batch[keys.OBS_IMAGE], cfg.augment_crop, cfg.augment_colour, state.generator)
        logits = net(image, batch[keys.OBS_STATE], active_actions(batch[keys.ACTION], net.cfg)).float()
        target = options.reward_scale * batch[keys.REWARD]
        loss = F.binary_cross_entropy_with_logits(logits, target)
        state.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        state.optimizer.step()
        q = logits.detach().sigmoid()
        return {"losses/q_loss": loss.item(), "q/mean": q.mean().item(), "q/target_mean": target.mean().item()}
