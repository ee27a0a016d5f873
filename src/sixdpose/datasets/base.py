"""The reader interface every later stage uses (synthetic layout and BOP alike).

Units: metres and radians everywhere in memory. BOP files (millimetres) are converted on read.
Frames follow Drake/OpenCV camera conventions: camera C has +x right, +y down, +z forward;
``R``/``t`` of an instance are ``X_CO`` (object O expressed in camera C): ``p_C = R @ p_O + t``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


class DatasetError(Exception):
    """A dataset on disk is missing, incomplete or malformed; the message names the file or field."""


@dataclass
class Instance:
    """One annotated object instance in one image.

    Attributes:
        obj_name: model name, e.g. ``"006_mustard_bottle"`` (BOP: ``"obj_000005"``).
        obj_id: integer object id (synthetic: 1-based index in ``TARGET_OBJECTS``; BOP: its id).
        inst: instance number of this object within the scene (0-based).
        R: (3, 3) float64 rotation of ``X_CO``.
        t: (3,) float64 translation of ``X_CO`` in metres.
        mask: (H, W) bool visible mask, or ``None`` if the split has no masks.
        px_visib: number of visible pixels (``-1`` if unknown).
    """

    obj_name: str
    obj_id: int
    inst: int
    R: np.ndarray
    t: np.ndarray
    mask: np.ndarray | None = None
    px_visib: int = -1


@dataclass
class Sample:
    """One RGB-D image with its annotations.

    Attributes:
        scene_id: scene number.
        im_id: image number (synthetic: the global image number ``#`` of the file names).
        rgb: (H, W, 3) uint8.
        depth: (H, W) float32 depth along the optical axis in metres, 0.0 where there is no
            measurement; ``None`` if the split has no depth.
        K: (3, 3) float64 camera intrinsics (pixel-centre convention: pixel (u, v) has its centre at
            integer coordinates, so ``p = K @ p_C / z`` gives the pixel index directly).
        instances: annotated instances.
    """

    scene_id: int
    im_id: int
    rgb: np.ndarray
    depth: np.ndarray | None
    K: np.ndarray
    instances: list[Instance] = field(default_factory=list)


@dataclass
class ObjectModel:
    """Reference model of one object.

    Attributes:
        obj_name, obj_id: as in :class:`Instance`.
        points: (N, 3) float64 model points in the object frame, metres.
        normals: (N, 3) float64 unit outward normals, or ``None``.
        colors: (N, 3) float64 RGB in [0, 1], or ``None``.
        diameter: largest distance between two model points, metres.
        symmetric: whether ADD-S (not ADD) applies.
    """

    obj_name: str
    obj_id: int
    points: np.ndarray
    normals: np.ndarray | None
    colors: np.ndarray | None
    diameter: float
    symmetric: bool


def collate_samples(batch: list[Sample]) -> list[Sample]:
    """``collate_fn`` for ``torch.utils.data.DataLoader``: keep samples as a list."""
    return list(batch)


def read_image(path: str | Path) -> np.ndarray:
    """Read an image file (PNG, JPEG, 16-bit PNG) into a numpy array.

    Raises:
        DatasetError: naming the file, if it is missing or not a readable image.
    """
    from PIL import Image

    try:
        with Image.open(path) as im:
            return np.asarray(im).copy()
    except FileNotFoundError:
        raise DatasetError(f"{path}: file not found") from None
    except Exception as e:  # PIL raises several types for truncated / non-image files
        raise DatasetError(f"{path}: unreadable image ({e})") from None


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Read a PLY point cloud or mesh (ascii or binary little endian) with Open3D.

    Returns:
        points (N, 3) float64 in the file's units, normals (N, 3) or ``None``, colors (N, 3) in [0, 1]
        or ``None``.
    Raises:
        DatasetError: the file is missing or unreadable.
    """
    import open3d as o3d

    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: model file not found")
    pcd = o3d.io.read_point_cloud(str(path))
    if len(pcd.points) == 0:
        raise DatasetError(f"{path}: no points could be read")
    pts = np.asarray(pcd.points, dtype=np.float64)
    nrm = np.asarray(pcd.normals, dtype=np.float64) if pcd.has_normals() else None
    col = np.asarray(pcd.colors, dtype=np.float64) if pcd.has_colors() else None
    return pts, nrm, col


def open_dataset(path: str | Path, split: str = "test", **kwargs):
    """Open a dataset directory, detecting its layout.

    Args:
        path: a synthetic dataset directory (has ``gt.yml``) or a BOP dataset root (has
            ``models/models_info.json``).
        split: BOP split name (ignored for the synthetic layout).
        **kwargs: passed to the reader class.
    Returns:
        A :class:`~sixdpose.datasets.synthetic.SyntheticDataset` or ``BopDataset``.
    Raises:
        DatasetError: the directory does not exist or is neither layout.
    """
    path = Path(path)
    if not path.is_dir():
        raise DatasetError(f"{path}: dataset directory not found")
    if (path / "gt.yml").is_file() or (path / "manifest.json").is_file():
        from .synthetic import SyntheticDataset

        return SyntheticDataset(path, **kwargs)
    if (path / "models" / "models_info.json").is_file():
        from .bop import BopDataset

        return BopDataset(path, split=split, **kwargs)
    raise DatasetError(
        f"{path}: not a dataset (no gt.yml for the synthetic layout, no models/models_info.json for BOP)"
    )
