"""Where the learner's arithmetic runs: ``cpu``, ``cuda`` or ``auto``.

``auto`` is ``cuda`` when torch sees an NVIDIA GPU and ``cpu`` otherwise;
asking for ``cuda`` where there is none is a one-line error that names the
fix.  A run records the device it resolved to (``TrainConfig.device``), and
the CPU, the default, is left out of the record, so the ids of checkpoints
trained before the option existed do not change.

What changes on a GPU (``learners/qtopt.py`` reads the same on both):

* random draws (augmentation, CEM noise, conservative candidates) come from a
  ``torch.Generator`` on the device, so a CUDA run reproduces on CUDA, not on
  the CPU;
* terminal transitions are masked instead of indexed out, so a step does not
  wait for the host to count them;
* metrics stay on the device until the loop logs them.

``NSL_DEVICE_CUDA=0`` makes nsl treat a machine as one without a GPU (``auto``
is then ``cpu``), as ``NSL_BF16=0`` does for the CPU's bfloat16.
"""

from __future__ import annotations

import os

import torch

from nsl.errors import ConfigError

DEVICES = ("cpu", "cuda", "auto")
CUDA_ENV = "NSL_DEVICE_CUDA"  # "0" (or "off", "false", "no"): act as if torch saw no GPU


def cuda_available() -> bool:
    """True when torch sees a CUDA device and ``NSL_DEVICE_CUDA`` does not switch it off."""
    if os.environ.get(CUDA_ENV, "").strip().lower() in ("0", "off", "false", "no"):
        return False
    return bool(torch.cuda.is_available())


def resolve_device(device: str) -> str:
    """``cpu``, ``cuda`` or ``auto`` -> ``cpu`` or ``cuda`` on this machine (one-line errors otherwise)."""
    if device not in DEVICES:
        raise ConfigError(f"device {device!r} is unknown; use one of {', '.join(DEVICES)}")
    if device == "auto":
        return "cuda" if cuda_available() else "cpu"
    if device == "cuda" and not cuda_available():
        raise ConfigError(
            "device cuda needs an NVIDIA GPU that torch can see (torch.cuda.is_available() is False here); "
            "use --device cpu, or auto to pick what this machine has"
        )
    return device


def generator(device: str, seed: int) -> torch.Generator:
    """A random generator on ``device`` seeded with ``seed`` (the CPU's is the one every CPU run used)."""
    return torch.Generator(device=device).manual_seed(seed)


def to_device(batch: dict[str, torch.Tensor], device: str) -> dict[str, torch.Tensor]:
    """The batch's tensors on ``device`` (the same tensors on the CPU; pinned, asynchronous copies on CUDA)."""
    if device == "cpu":
        return batch
    return {k: v if v.device.type == device else v.pin_memory().to(device, non_blocking=True) for k, v in batch.items()}
