"""The procedural object library: PyBullet's 1000 ``random_urdfs`` meshes.

The train split is the folders whose number does not end in 0 and the test
split the folders that do, as in PyBullet's ``KukaDiverseObjectEnv``.  Meshes
are parsed once per process into centred vertex/face arrays, and scaled so
that an object is graspable: its middle extent falls in a realistic range.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nsl.errors import ConfigError, CorruptDataError, EnvironmentSetupError

SPLITS = ("train", "test")


@dataclass(frozen=True)
class MeshData:
    """A unit mesh: vertices centred on their bounding box, unscaled."""

    name: str
    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int32
    extents: np.ndarray  # (3,) bounding-box size

    def __repr__(self) -> str:
        return (
            f"MeshData({self.name!r}, vertices={self.vertices.shape}, "
            f"faces={self.faces.shape}, extents={np.round(self.extents, 3).tolist()})"
        )


@functools.cache
def urdf_root() -> Path:
    try:
        import pybullet_data
    except ImportError as e:  # pragma: no cover - pybullet is a dependency
        raise EnvironmentSetupError(
            "pybullet_data is not importable; install nsl's dependencies with `make install`"
        ) from e
    root = Path(pybullet_data.getDataPath()) / "random_urdfs"
    if not root.is_dir():
        raise EnvironmentSetupError(f"{root} is missing; reinstall pybullet (`pip install pybullet`)")
    return root


_VERTEX = re.compile(rb"^v\s+(\S+)\s+(\S+)\s+(\S+)", re.M)
_TRIANGLE = re.compile(rb"^f\s+(-?\d+)\S*\s+(-?\d+)\S*\s+(-?\d+)\S*\s*$", re.M)


def parse_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangulated faces of a Wavefront OBJ file.

    Triangle-only files (nearly all of random_urdfs) are parsed with two
    regular expressions; files with polygons are fan-triangulated line by line.
    """
    data = Path(path).read_bytes()
    v = np.array(_VERTEX.findall(data), dtype=np.float64).reshape(-1, 3)
    tris = _TRIANGLE.findall(data)
    if len(tris) == len(re.findall(rb"^f\s", data, re.M)):
        fc: np.ndarray = np.array(tris, dtype=np.int64).reshape(-1, 3)
    else:
        faces: list[list[int]] = []
        for line in data.decode().splitlines():
            if line.startswith("f "):
                idx = [int(tok.split("/")[0]) for tok in line.split()[1:]]
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
        fc = np.array(faces, dtype=np.int64).reshape(-1, 3)
    fc = np.where(fc > 0, fc - 1, len(v) + fc).astype(np.int32)  # 1-based, or negative = from the end
    return v, fc


@functools.cache
def load_mesh(object_id: int) -> MeshData:
    """Parse object ``object_id`` (0..999) once per process."""
    name = f"{object_id:03d}"
    path = urdf_root() / name / f"{name}.obj"
    v, fc = parse_obj(path)
    if len(v) < 4 or not np.isfinite(v).all():
        raise CorruptDataError(f"mesh {path} has non-finite or too few vertices; it is excluded")
    lo, hi = v.min(0), v.max(0)
    return MeshData(name, v - (lo + hi) / 2, fc, hi - lo)


@functools.cache
def object_ids(split: str) -> tuple[int, ...]:
    """Usable object ids of a split (meshes with broken geometry are left out)."""
    if split not in SPLITS:
        raise ConfigError(f"object split {split!r} is not one of {SPLITS}; use --split train or test")
    ids = []
    for d in sorted(urdf_root().iterdir()):
        if not (d.is_dir() and d.name.isdigit()) or not (d / f"{d.name}.obj").exists():
            continue
        i = int(d.name)
        if (i % 10 == 0) != (split == "test"):
            continue
        raw = (d / f"{d.name}.obj").read_bytes().lower()
        if b"nan" in raw or b"inf" in raw:  # e.g. 168.obj: MuJoCo refuses non-finite vertices
            continue
        ids.append(i)
    return tuple(ids)


def scale_for(mesh: MeshData, middle_extent: float, min_extent: float = 0.018) -> np.ndarray:
    """Per-axis scale giving the mesh's middle extent the requested size.

    The middle of the three extents sets a uniform scale: a few meshes have one
    extent near zero, and the largest extent of long objects would shrink them
    below graspable size.  Axes that would then be thinner than ``min_extent``
    are thickened to it, so that a flat object lying in the bin still stands
    tall enough between the fingers (wafer-thin objects are ungraspable for a
    parallel jaw in the real study too).
    """
    s = middle_extent / float(np.sort(mesh.extents)[1])
    ext = np.maximum(mesh.extents, 1e-6) * s
    return s * np.maximum(1.0, min_extent / ext)
