"""Glue: turn command-line references into objects from the folders.

``policy_factory`` maps a policy reference to a picklable zero-argument
callable that builds the policy inside each worker process.
"""

from __future__ import annotations

import functools
from collections.abc import Callable


def policy_factory(ref: str, env_config) -> Callable:
    """``random`` | ``oracle[:NOISE]`` -> a picklable policy factory."""
    from nsl.collectors import scripted_policy

    factory = functools.partial(scripted_policy, ref, control=env_config.control, move_step=env_config.move_step,
                                yaw_step=env_config.yaw_step)
    factory()  # validate the reference now, before any worker starts
    return factory
