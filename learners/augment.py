"""Image preprocessing and augmentation, batched in torch (no per-sample Python loops).

* :func:`random_shift` is the random crop with padding of DrQ / RAD: pad by
  ``pad`` pixels (edge pixels repeated) and crop back at a random offset.  It
  is done by index arithmetic on the uint8 (B, H, W, 3) batch, so padding
  never materialises.
* :func:`colour_jitter` scales brightness, contrast and each channel's gain
  by random factors per image.

Both draw from an explicit ``torch.Generator`` so a run is reproducible.
"""

from __future__ import annotations

import torch


def to_float(images: torch.Tensor, channels_last: bool = True) -> torch.Tensor:
    """uint8 (B, H, W, 3) -> float (B, 3, H, W) in [0, 1], in channels_last memory format if asked."""
    x = images.permute(0, 3, 1, 2).float().mul_(1.0 / 255.0)  # an NHWC buffer is channels_last already
    return x if channels_last else x.contiguous()


def random_shift(images: torch.Tensor, pad: int, generator: torch.Generator) -> torch.Tensor:
    """Shift each uint8 image (B, H, W, C) by a random offset in [-pad, pad]^2, repeating edge pixels."""
    if pad <= 0:
        return images
    b, h, w, c = images.shape
    dev = images.device
    off = torch.randint(-pad, pad + 1, (b, 2), generator=generator, device=generator.device)
    rows = (torch.arange(h, device=dev).unsqueeze(0) + off[:, :1]).clamp_(0, h - 1)
    cols = (torch.arange(w, device=dev).unsqueeze(0) + off[:, 1:]).clamp_(0, w - 1)
    pixel = (torch.arange(b, device=dev).view(b, 1, 1) * (h * w) + rows.view(b, h, 1) * w + cols.view(b, 1, w)).view(-1)
    return images.reshape(b * h * w, c).index_select(0, pixel).view(b, h, w, c)


def colour_jitter(x: torch.Tensor, strength: float, generator: torch.Generator) -> torch.Tensor:
    """Random brightness, contrast and per-channel gain on float images (B, 3, H, W) in [0, 1].

    One fused affine map per image and channel: ``x * scale + offset``, clamped.
    """
    if strength <= 0:
        return x
    b, c = x.shape[:2]
    u = torch.rand(b, 2 + c, generator=generator, device=generator.device) * 2.0 - 1.0
    brightness, contrast = 1.0 + strength * u[:, :1], 1.0 + strength * u[:, 1:2]
    gain = 1.0 + 0.5 * strength * u[:, 2:]
    mean = x.mean(dim=(1, 2, 3)).unsqueeze(1)
    scale = contrast * brightness * gain  # (B, C)
    offset = mean * (1.0 - contrast) * brightness * gain
    return torch.addcmul(offset.view(b, c, 1, 1), x, scale.view(b, c, 1, 1)).clamp_(0.0, 1.0)


def prepare_images(
    images: torch.Tensor, crop: int, colour: float, generator: torch.Generator | None, channels_last: bool = True
) -> torch.Tensor:
    """uint8 (B, H, W, 3) -> augmented float (B, 3, H, W); no augmentation without a generator.

    Element-wise work runs on a contiguous NCHW copy (broadcasting over
    channels_last is several times slower on CPU), then the batch is laid out
    channels_last for the convolutions if asked.
    """
    if generator is not None:
        images = random_shift(images, crop, generator)
    x = to_float(images, channels_last=False)
    if generator is not None:
        x = colour_jitter(x, colour, generator)
    return x.contiguous(memory_format=torch.channels_last) if channels_last else x
