"""Scripted collection policies and the policy interface.

A policy maps a batch of observations to a batch of actions::

    actions = policy(obs, rngs=rngs, privileged=privileged)

``obs`` is a dict of stacked arrays (``image`` (B, H, W, 3) uint8, ``state``
(B, 2) float32).  ``rngs`` holds one ``numpy.random.Generator`` per episode,
so an episode's actions depend only on its own seed, never on which worker or
batch it ran in.  ``privileged`` is a list of ground-truth dicts, given only
to policies whose ``needs_privileged`` is true (the scripted oracle).  A
learned policy (a checkpoint's CEM policy from ``nsl.learners``) has the same
call signature and is passed in by the caller.

On the command line: ``random`` and ``oracle[:NOISE]``, and a plugin's ``PACKAGE.NAME[:ARGS]``
(an ``nsl.policies`` entry point, or :func:`register_policy`; docs/extending.md).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Protocol

import numpy as np

from nsl.errors import ConfigError, unknown
from nsl.keys import ACTION_DIM


class Policy(Protocol):
    name: str
    needs_privileged: bool

    def __call__(
        self,
        obs: dict[str, np.ndarray],
        *,
        rngs: list[np.random.Generator],
        privileged: list[dict[str, np.ndarray]] | None = None,
    ) -> np.ndarray: ...

    def describe(self) -> dict[str, Any]: ...


@dataclass
class RandomPolicy:
    """Uniform random steering, biased to descend and to grasp late (QT-Opt's first collection)."""

    terminate_prob: float = 0.05  # chance per step of grasping early
    control: str = "auto_descent"
    name: str = "random"
    needs_privileged: bool = False

    def __call__(self, obs, *, rngs, privileged=None):
        out = np.empty((len(rngs), ACTION_DIM), dtype=np.float32)
        for i, rng in enumerate(rngs):
            a = rng.uniform(-1.0, 1.0, ACTION_DIM)
            a[2] = rng.uniform(-1.0, 0.3)  # biased down
            low = obs["state"][i, 1] < 0.12
            a[4] = 1.0 if (self.control == "full" and low and rng.random() < 0.5) else -1.0
            a[5] = 1.0 if rng.random() < self.terminate_prob else -1.0
            out[i] = a
        return out

    def describe(self) -> dict[str, Any]:
        return {"policy": "random", **{k: v for k, v in asdict(self).items() if k not in ("name",)}}


def _wrap_half_pi(a: np.ndarray | float) -> np.ndarray | float:
    """Wrap an angle to [-pi/2, pi/2): a parallel jaw is symmetric under pi."""
    return (a + math.pi / 2) % math.pi - math.pi / 2


@dataclass
class OraclePolicy:
    """Privileged scripted grasping with Gaussian action noise.

    It steers the fingers' centre over the object nearest to them and turns
    the jaw across the object's narrowest horizontal width.  ``noise`` is the
    standard deviation added to every action component; it tunes the success
    rate from near-perfect (0) towards random.
    """

    noise: float = 0.0
    move_step: float = 0.03  # must match the environment's EnvConfig.move_step
    yaw_step: float = 0.35
    workspace: float = 0.13  # wrist x/y reach (scene.WORKSPACE_HALF)
    control: str = "auto_descent"
    name: str = "oracle"
    needs_privileged: bool = True

    def __post_init__(self) -> None:
        if not (0.0 <= self.noise <= 5.0):
            raise ConfigError(f"oracle noise {self.noise!r} is out of range; use 0..5 (e.g. oracle:0.3)")

    def __call__(self, obs, *, rngs, privileged=None):
        if privileged is None:
            raise ConfigError("the oracle policy needs the environment's privileged state")
        out = np.zeros((len(rngs), ACTION_DIM), dtype=np.float32)
        for i, (rng, p) in enumerate(zip(rngs, privileged)):
            x, y, z, yaw = p["gripper"]
            off = p["finger_offset"]
            c, s = math.cos(yaw), math.sin(yaw)
            centre = np.array([x + c * off[0] - s * off[1], y + s * off[0] + c * off[1]])
            d = p["object_pos"][:, :2] - centre
            k = int(np.argmin((d**2).sum(1)))
            # A parallel jaw can grasp at yaw or yaw + pi; with an offset gripper the two
            # put the wrist in different places, so take the one that keeps it in reach.
            best = None
            for cand in (p["object_grasp_yaw"][k], p["object_grasp_yaw"][k] + math.pi):
                err = (cand - yaw + math.pi) % (2 * math.pi) - math.pi
                goal_yaw = yaw + err
                if abs(goal_yaw) > math.pi:
                    continue
                cg, sg = math.cos(goal_yaw), math.sin(goal_yaw)
                wrist_goal = p["object_pos"][k, :2] - np.array([cg * off[0] - sg * off[1], sg * off[0] + cg * off[1]])
                cost = float(np.abs(wrist_goal).max() > self.workspace) * 10 + abs(err)
                if best is None or cost < best[0]:
                    best = (cost, err, wrist_goal)
            _, yaw_err, wrist_goal = best
            # Steer the wrist so the fingers' centre ends over the object at the goal yaw.
            delta = wrist_goal - np.array([x, y])
            if np.hypot(*off) < 1e-6:
                yaw_err = float(_wrap_half_pi(yaw_err))
            a = np.zeros(ACTION_DIM)
            a[:2] = np.clip(delta / self.move_step, -1, 1)
            a[3] = np.clip(yaw_err / self.yaw_step, -1, 1)
            aligned = np.linalg.norm(delta) < 0.01 and abs(yaw_err) < 0.15
            if self.control == "full":
                a[2] = -1.0 if aligned else 0.0
                a[4] = 1.0 if (aligned and obs["state"][i, 1] < 0.08) else -1.0
            else:
                a[4] = -1.0
            a[5] = -1.0
            if self.noise > 0:
                a[:4] += rng.normal(0.0, self.noise, 4)
            out[i] = np.clip(a, -1, 1)
        return out

    def describe(self) -> dict[str, Any]:
        return {"policy": "oracle", **{k: v for k, v in asdict(self).items() if k not in ("name",)}}


SCRIPTED = {"random": RandomPolicy, "oracle": OraclePolicy}
_REGISTERED: dict[str, tuple[Any, dict[str, str]]] = {}  # plugin policies registered in this process


def register_policy(name: str, factory, plugin: dict[str, str] | None = None) -> None:
    """Add a collection policy ``--policy NAME[:ARGS]`` for this process; ``NAME`` is ``PACKAGE.NAME``.

    ``factory(args, *, control, move_step, yaw_step)`` returns a :class:`Policy` (``args``: the text after the
    colon, or "").  Packages declare theirs as ``nsl.policies`` entry points instead (docs/extending.md).
    """
    if "." not in name or name.startswith(("ckpt", ".")) or not callable(factory):
        raise ConfigError(
            f"policy name {name!r}: a plugin policy is named PACKAGE.NAME and registered with a callable "
            "factory(args, *, control, move_step, yaw_step)"
        )
    _REGISTERED[name] = (factory, plugin or {"package": "__main__", "version": "0"})


class PluginPolicy:
    """A plugin's policy, whose description records the plugin's package and version."""

    def __init__(self, inner: Any, ref: str, plugin: dict[str, str]):
        self.inner, self.ref, self.plugin = inner, ref, plugin
        self.name = ref.partition(":")[0]
        self.needs_privileged = bool(getattr(inner, "needs_privileged", False))

    def __call__(self, obs, *, rngs, privileged=None):
        return self.inner(obs, rngs=rngs, privileged=privileged)

    def describe(self) -> dict[str, Any]:
        inner = self.inner.describe() if hasattr(self.inner, "describe") else {}
        return {"policy": self.ref, **inner, "plugin": dict(self.plugin)}


def _plugin_policy(ref: str, control: str, move_step: float, yaw_step: float) -> Policy | None:
    name, _, arg = ref.partition(":")
    if "." not in name:
        return None
    if name not in _REGISTERED:
        from nsl import plugins

        found = plugins.load("nsl.policies", name)
        if found is None:
            raise unknown(
                "policy",
                ref,
                [*SCRIPTED, *_REGISTERED, *plugins.names("nsl.policies")],
                "a plugin policy is PACKAGE.NAME from an installed package's nsl.policies entry points",
            )
        _REGISTERED[name] = found
    factory, plugin = _REGISTERED[name]
    return PluginPolicy(factory(arg, control=control, move_step=move_step, yaw_step=yaw_step), ref, plugin)


def scripted_policy(ref: str, control: str = "auto_descent", move_step: float = 0.03, yaw_step: float = 0.35) -> Policy:
    """Build a scripted policy from ``random``, ``oracle[:NOISE]`` or a plugin's ``PACKAGE.NAME[:ARGS]``."""
    plugin = _plugin_policy(ref, control, move_step, yaw_step)
    if plugin is not None:
        return plugin
    name, _, arg = ref.partition(":")
    if name not in SCRIPTED:
        raise unknown(
            "policy", ref, [*SCRIPTED, "oracle:NOISE", "ckpt:NAME"], "scripted policies are random and oracle[:NOISE]"
        )
    if name == "random":
        if arg:
            raise ConfigError(f"policy {ref!r}: random takes no argument; write `random`")
        return RandomPolicy(control=control)
    try:
        noise = float(arg) if arg else 0.0
    except ValueError:
        raise ConfigError(f"policy {ref!r}: noise {arg!r} is not a number; write e.g. oracle:0.3") from None
    return OraclePolicy(noise=noise, control=control, move_step=move_step, yaw_step=yaw_step)
