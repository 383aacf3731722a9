"""The shift gallery: first frames of several episodes per shift, as one PNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .env import EnvConfig, GraspEnv
from .render import SceneRenderer
from .shifts import ShiftSpec


def render_gallery(
    shifts: list[ShiftSpec],
    out: Path,
    episodes: int = 4,
    seed: int = 0,
    image_size: int = 64,
    scale: int = 3,
    split: str = "train",
    engine: str = "mujoco",
) -> Path:
    """Write a grid with one row per shift and one column per episode.

    Column ``k`` uses the same scene seed in every row, so a row differs from
    the base row only by its shift.  Frames are upscaled ``scale`` times with
    nearest-neighbour so a person sees the pixels the learner sees.
    """
    from PIL import Image, ImageDraw

    configs = [EnvConfig(shift=spec.name, image_size=image_size, split=split, engine=engine) for spec in shifts]
    renderer = SceneRenderer(image_size, image_size) if engine == "mujoco" else None  # one GL context for all rows
    rows = []
    try:
        for config in configs:
            env = GraspEnv(config, renderer=renderer)
            frames = [env.reset(seed=seed + k)[0]["image"] for k in range(episodes)]
            env.close()
            rows.append(np.concatenate(frames, axis=1))
    finally:
        if renderer is not None:
            renderer.close()
    grid = np.concatenate(rows, axis=0)
    img = Image.fromarray(grid).resize((grid.shape[1] * scale, grid.shape[0] * scale), Image.Resampling.NEAREST)
    label_w = 170
    canvas = Image.new("RGB", (img.width + label_w, img.height), "white")
    canvas.paste(img, (label_w, 0))
    draw = ImageDraw.Draw(canvas)
    cell = image_size * scale
    for r, spec in enumerate(shifts):
        draw.text((6, r * cell + cell // 2 - 6), spec.name.replace("+", "+\n"), fill="black")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp.png")
    canvas.save(tmp)
    tmp.replace(out)
    return out
