"""Running policies in environments: episodes as records, in lock-step batches.

Episode ``i`` of a collection with seed ``s`` is a pure function of ``(s, i)``:
its scene seed and its policy's random generator both come from
``numpy.random.SeedSequence([s, i])``.  Running it alone, in a batch, in any
worker, or after an interruption gives the same episode.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .env import EnvConfig, GraspEnv
from .policies import Policy


@dataclass(frozen=True)
class Episode:
    """One grasp attempt: T frames, each the observation before an action."""

    index: int
    images: np.ndarray  # (T, H, W, 3) uint8
    states: np.ndarray  # (T, STATE_DIM) float32
    actions: np.ndarray  # (T, 6) float32
    rewards: np.ndarray  # (T,) float32
    terminated: bool
    truncated: bool
    success: bool
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def length(self) -> int:
        return int(len(self.actions))

    def __repr__(self) -> str:
        return (
            f"Episode(index={self.index}, length={self.length}, success={self.success}, "
            f"images={self.images.shape}:{self.images.dtype}, actions={self.actions.shape}, "
            f"terminated={self.terminated}, truncated={self.truncated})"
        )


def episode_seeds(seed: int, index: int) -> tuple[int, np.random.Generator]:
    """The scene seed and the policy generator of episode ``index``."""
    env_ss, pol_ss = np.random.SeedSequence([int(seed), int(index)]).spawn(2)
    return int(env_ss.generate_state(1)[0]), np.random.default_rng(pol_ss)


def run_episodes(envs: list[GraspEnv], policy: Policy, indices: Iterable[int], seed: int) -> Iterator[Episode]:
    """Run episodes ``indices`` with ``len(envs)`` environments stepping in lock-step.

    The policy is called once per step on the stacked observations of every
    running environment.  Episodes are yielded in index order.
    """
    indices = list(indices)
    for start in range(0, len(indices), len(envs)):
        chunk = indices[start : start + len(envs)]
        yield from _run_batch(envs[: len(chunk)], policy, chunk, seed)


def _run_batch(envs: list[GraspEnv], policy: Policy, indices: list[int], seed: int) -> list[Episode]:
    n = len(envs)
    rngs, obs = [], []
    for env, i in zip(envs, indices):
        env_seed, rng = episode_seeds(seed, i)
        o, _ = env.reset(seed=env_seed)
        rngs.append(rng)
        obs.append(o)
    frames: list[dict[str, list]] = [{"images": [], "states": [], "actions": [], "rewards": []} for _ in range(n)]
    ends: list[dict[str, Any] | None] = [None] * n
    active = list(range(n))
    while active:
        batch = {k: np.stack([obs[j][k] for j in active]) for k in obs[active[0]]}
        privileged = [envs[j].privileged_state() for j in active] if policy.needs_privileged else None
        actions = np.asarray(policy(batch, rngs=[rngs[j] for j in active], privileged=privileged), dtype=np.float32)
        still = []
        for a, j in zip(actions, active):
            f = frames[j]
            f["images"].append(obs[j]["image"])
            f["states"].append(obs[j]["state"])
            f["actions"].append(a)
            o, r, term, trunc, info = envs[j].step(a)
            f["rewards"].append(r)
            obs[j] = o
            if term or trunc:
                ends[j] = {
                    "terminated": term,
                    "truncated": trunc,
                    "success": bool(info["success"]),
                    "num_objects": info["num_objects"],
                }
            else:
                still.append(j)
        active = still
    out = []
    for j, i in enumerate(indices):
        f, e = frames[j], ends[j]
        assert e is not None  # the loop above runs until every episode has ended
        out.append(
            Episode(
                index=i,
                images=np.stack(f["images"]),
                states=np.stack(f["states"]).astype(np.float32),
                actions=np.stack(f["actions"]).astype(np.float32),
                rewards=np.asarray(f["rewards"], dtype=np.float32),
                terminated=e["terminated"],
                truncated=e["truncated"],
                success=e["success"],
                info={"num_objects": e["num_objects"]},
            )
        )
    return out


def make_envs(config: EnvConfig, count: int) -> list[GraspEnv]:
    """``count`` environments; on MuJoCo they share one renderer (one GL context per process)."""
    if config.engine != "mujoco":
        return [GraspEnv(config) for _ in range(count)]
    from .render import SceneRenderer

    renderer = SceneRenderer(config.image_size, config.image_size)
    return [GraspEnv(config, renderer=renderer) for _ in range(count)]


PolicyFactory = Callable[[], Policy]
