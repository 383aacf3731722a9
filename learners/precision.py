"""Numeric precision of the Q-network's passes: float32, or bfloat16 where the hardware computes it natively.

Weights, gradients and the optimiser's state stay float32 in both.  With
``bf16`` the forward and backward passes run under
``torch.autocast("cpu", dtype=torch.bfloat16)``: convolutions and matrix
products take bfloat16 inputs (AVX-512 BF16 or AMX units) and accumulate in
float32; the log loss and the Bellman targets are computed in float32.

``auto`` resolves to ``bf16`` where the CPU supports it and to ``fp32``
elsewhere; asking for ``bf16`` on a CPU without it is an error.

On a GPU (``learners/device.py``) ``bf16`` autocasts to bfloat16 on CUDA where
the GPU has it (every NVIDIA GPU since Ampere), ``auto`` is ``bf16`` there,
and float32 convolutions use TensorFloat-32, PyTorch's default for cuDNN.

``NSL_BF16=0`` in the environment makes nsl treat the CPU as one without
bfloat16 (``auto`` is then ``fp32``): the common case on rented cloud machines,
and how the test suite checks that it passes there too.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import torch

from nsl.errors import ConfigError

PRECISIONS = ("fp32", "bf16", "auto")
BF16_ENV = "NSL_BF16"  # "0" (or "off", "false", "no"): act as if this CPU had no bfloat16 arithmetic


def bf16_supported() -> bool:
    """True when this CPU has native bfloat16 arithmetic (AVX-512 BF16 or AMX tiles) that torch can use, and
    ``NSL_BF16`` does not switch it off."""
    if os.environ.get(BF16_ENV, "").strip().lower() in ("0", "off", "false", "no"):
        return False
    cpu = getattr(torch._C, "_cpu", None)
    if cpu is None:
        return False
    checks = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
    return any(bool(getattr(cpu, name, lambda: False)()) for name in checks)


def resolve_precision(precision: str, device: str = "cpu") -> str:
    """``fp32``, ``bf16`` or ``auto`` -> ``fp32`` or ``bf16`` for this machine's ``device`` (``cpu`` or ``cuda``;
    one-line errors otherwise)."""
    if precision not in PRECISIONS:
        raise ConfigError(f"precision {precision!r} is unknown; use one of {', '.join(PRECISIONS)}")
    if device == "cuda":
        has = bool(torch.cuda.is_bf16_supported())
        if precision == "bf16" and not has:
            raise ConfigError("precision bf16 needs a GPU with bfloat16 (Ampere or newer); use --precision fp32")
        return ("bf16" if has else "fp32") if precision == "auto" else precision
    if precision == "auto":
        return "bf16" if bf16_supported() else "fp32"
    if precision == "bf16" and not bf16_supported():
        raise ConfigError(
            "precision bf16 needs a CPU with AVX-512 BF16 or AMX (lscpu: avx512_bf16, amx_bf16); "
            "use --precision fp32, or auto to pick what this machine has"
        )
    return precision


@contextlib.contextmanager
def autocast(precision: str, device: str = "cpu") -> Iterator[None]:
    """The passes inside run in ``precision`` (``fp32``: unchanged; ``bf16``: autocast to bfloat16 on ``device``)."""
    if precision == "bf16":
        # No cast cache on a GPU: a captured CUDA graph must recompute the weights' casts on every replay.
        with torch.autocast(device, dtype=torch.bfloat16, cache_enabled=device == "cpu"):
            yield
    else:
        yield
