"""``nsl render``: an image grid of episodes' first frames, one row per shift."""

from __future__ import annotations

import argparse
from pathlib import Path

from nsl.commands._options import add_parser, add_seed
from nsl.services.options import ENGINE_HELP, ENGINES


def register(sub: argparse._SubParsersAction) -> None:
    p = add_parser(
        sub,
        "render",
        help="write a PNG grid of first frames per shift (like Fig. 5.2)",
        description="Render the first camera frame of several episodes for one shift or all of them. "
        "Columns share scene seeds, so each row differs from the base row only by its shift.",
    )
    p.add_argument(
        "--shift",
        default="all",
        help="shift spec (e.g. harsh_lighting, harsh_lighting+checkerboard_backing@0.5) or 'all' for one row per shift",
    )
    p.add_argument("--severity", type=float, default=None, help="severity for shifts given without @X (default 1.0)")
    p.add_argument("--episodes", type=int, default=4, help="columns: episodes per shift")
    p.add_argument("--image-size", type=int, default=64, help="camera resolution in pixels")
    p.add_argument("--scale", type=int, default=3, help="upscaling factor for viewing")
    add_seed(p, help="scene seed: column i shows scene (seed, i)")
    p.add_argument("--split", default="train", choices=["train", "test"], help="object split")
    p.add_argument("--engine", default=ENGINES[0], choices=ENGINES, help=ENGINE_HELP)
    p.add_argument("--out", type=Path, default=Path("gallery.png"), help="output PNG")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from nsl.collectors import parse_shift_list, render_gallery
    from nsl.errors import ConfigError

    if args.episodes < 1 or args.scale < 1:
        raise ConfigError("--episodes and --scale must be at least 1")
    shifts = parse_shift_list(args.shift, args.severity)
    out = render_gallery(
        shifts,
        args.out,
        episodes=args.episodes,
        seed=args.seed,
        image_size=args.image_size,
        scale=args.scale,
        split=args.split,
        engine=args.engine,
    )
    print(f"wrote {out} ({len(shifts)} rows x {args.episodes} episodes)")
    return 0
