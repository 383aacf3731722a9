"""Feature statistics in LeRobot's shape: ``min``, ``max``, ``mean``, ``std``, ``count`` and the
quantiles ``q01``, ``q10``, ``q50``, ``q90``, ``q99``.

Per episode they are computed from the raw arrays when the episode is written
and stored as ``stats/<feature>/<stat>`` columns of ``meta/episodes`` (as LeRobot
does); ``meta/stats.json`` pools them, so appending episodes never re-reads old
images. Counts, means and variances combine exactly; quantiles pool as LeRobot's
``aggregate_stats`` pools them, as the count-weighted mean of the episodes'
quantiles (an approximation of the pooled quantile that LeRobot's ``QUANTILES``
normalisation reads). Episodes written before quantiles were recorded have none,
and a pool that holds any of them has none either (as in LeRobot).

Conventions (LeRobot's): images are scaled to [0, 1] and reduced per channel
to shape (3, 1, 1); vectors keep their dimension; scalar features have shape
(1,); ``std`` is the population standard deviation; bool features keep bool
``min``/``max``. An episode's quantiles are exact (numpy's linear interpolation,
where LeRobot's histogram estimates them).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)
QUANTILE_NAMES = tuple(f"q{round(q * 100):02d}" for q in QUANTILES)  # LeRobot's keys: q01 .. q99
STAT_NAMES = ("min", "max", "mean", "std", "count", *QUANTILE_NAMES)

Stats = dict[str, dict[str, np.ndarray]]


def feature_stats(values: np.ndarray, is_image: bool = False) -> dict[str, np.ndarray]:
    """Stats of one feature over the first axis (frames)."""
    values = np.asarray(values)
    n = len(values)
    if n == 0:
        raise ValueError("cannot compute stats of an empty feature")
    if is_image:  # (T, H, W, C) uint8 -> per channel, in [0, 1], shape (C, 1, 1)
        import cv2

        c = values.shape[-1]
        tall = np.ascontiguousarray(values).reshape(-1, values.shape[-2], c)  # frames stacked vertically
        mean, std = (a.reshape(-1) for a in cv2.meanStdDev(tall))  # exact: sums in float64
        rows = tall.reshape(len(tall), -1)  # row-wise reductions vectorise; strided (N, 3) ones do not
        shape = (-1, 1, 1)
        quantiles = _uint8_quantiles(tall) / 255.0  # (5, C)
        return {
            "min": (rows.min(0).reshape(-1, c).min(0) / 255.0).reshape(shape),
            "max": (rows.max(0).reshape(-1, c).max(0) / 255.0).reshape(shape),
            "mean": (mean / 255.0).reshape(shape),
            "std": (std / 255.0).reshape(shape),
            "count": np.array([n]),
            **{name: q.reshape(shape) for name, q in zip(QUANTILE_NAMES, quantiles)},
        }
    flat = values.reshape(n, -1)
    as_float = flat.astype(np.float64)
    return {
        "min": flat.min(0),
        "max": flat.max(0),
        "mean": as_float.mean(0),
        "std": as_float.std(0),
        "count": np.array([n]),
        **dict(zip(QUANTILE_NAMES, np.quantile(as_float, QUANTILES, axis=0))),
    }


def _uint8_quantiles(tall: np.ndarray) -> np.ndarray:
    """``np.quantile(pixels, QUANTILES, axis=0)`` per channel of (rows, W, C) uint8 pixels, from histograms."""
    import cv2

    rows, width, c = tall.shape
    step = max(1, 2**23 // width)  # cv2 counts in float32: exact below 2**24 per call
    hist = np.zeros((c, 256), np.int64)
    for i in range(0, rows, step):
        for k in range(c):
            hist[k] += cv2.calcHist([tall[i : i + step]], [k], None, [256], [0, 256]).ravel().astype(np.int64)
    cum = hist.cumsum(1)
    n = rows * width
    pos = np.asarray(QUANTILES) * (n - 1)  # numpy's "linear" method: between sorted ranks floor and ceil
    lo = np.floor(pos)
    # The value of sorted rank r in channel k is the first bin whose cumulative count exceeds r.
    low, high = (np.stack([np.searchsorted(cum[k], r, side="right") for k in range(c)], 1) for r in (lo, np.ceil(pos)))
    return low + (pos - lo)[:, None] * (high - low)  # (5, C)


def episode_stats(frames: dict[str, np.ndarray], image_keys: Iterable[str]) -> Stats:
    """Stats of every feature of one episode (``frames`` maps key -> (T, ...) array)."""
    image_keys = set(image_keys)
    return {k: feature_stats(v, k in image_keys) for k, v in frames.items()}


def aggregate(parts: list[Stats]) -> Stats:
    """Pool per-episode stats exactly: counts add, means and variances combine."""
    if not parts:
        raise ValueError("no stats to aggregate")
    out: Stats = {}
    for key in parts[0]:
        counts = np.array([float(p[key]["count"][0]) for p in parts])
        means = np.stack([np.asarray(p[key]["mean"], dtype=np.float64) for p in parts])
        stds = np.stack([np.asarray(p[key]["std"], dtype=np.float64) for p in parts])
        w = counts.reshape((-1,) + (1,) * (means.ndim - 1))
        total = counts.sum()
        mean = (w * means).sum(0) / total
        var = (w * (stds**2 + (means - mean) ** 2)).sum(0) / total
        mins = np.stack([np.asarray(p[key]["min"]) for p in parts])
        maxs = np.stack([np.asarray(p[key]["max"]) for p in parts])
        out[key] = {
            "min": mins.min(0),
            "max": maxs.max(0),
            "mean": mean,
            "std": np.sqrt(np.maximum(var, 0.0)),
            "count": np.array([int(total)]),
        }
        if all(q in p[key] for p in parts for q in QUANTILE_NAMES):  # LeRobot's aggregate_feature_stats
            for q in QUANTILE_NAMES:
                values = np.stack([np.asarray(p[key][q], dtype=np.float64) for p in parts])
                out[key][q] = (w * values).sum(0) / total
    return out


def to_json(stats: Stats) -> dict[str, dict[str, Any]]:
    """JSON-ready nested lists (the content of ``meta/stats.json``)."""
    return {k: {s: np.asarray(v[s]).tolist() for s in STAT_NAMES if s in v} for k, v in stats.items()}


def from_json(d: dict[str, dict[str, Any]]) -> Stats:
    return {k: {s: np.asarray(v[s]) for s in STAT_NAMES if s in v} for k, v in d.items()}


def to_columns(stats: Stats) -> dict[str, Any]:
    """Flatten to ``stats/<feature>/<stat>`` values (one row of ``meta/episodes``)."""
    return {f"stats/{k}/{s}": np.asarray(v[s]).tolist() for k, v in stats.items() for s in STAT_NAMES if s in v}


def from_columns(row: dict[str, Any]) -> Stats:
    """Inverse of :func:`to_columns` for one episode row."""
    out: Stats = {}
    for col, value in row.items():
        if not col.startswith("stats/"):
            continue
        key, _, stat = col[len("stats/") :].rpartition("/")
        out.setdefault(key, {})[stat] = np.asarray(value)
    return out
