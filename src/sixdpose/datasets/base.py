"""The reader interface every later stage uses (synthetic layout and BOP alike).

Units: metres and radians everywhere in memory. BOP files (millimetres) are converted on read.
Frames follow Drake/OpenCV camera conventions: camera C has +x right, +y down, +z forward;
``R``/``t`` of an instance are ``X_CO`` (object O expressed in camera C): ``p_C = R @ p_O + t``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from ..errors import SixdposeError

#: An image key: ``(scene_id, im_id)``.
Key = tuple[int, int]


class DatasetError(SixdposeError):
    """A dataset on disk is missing, incomplete or malformed; the message names the file or field."""


@dataclass
class Instance:
    """One annotated object instance in one image.

    Attributes:
        obj_name: model name, e.g. ``"006_mustard_bottle"`` (BOP: ``"obj_000005"``).
        obj_id: integer object id (synthetic: 1-based index in ``TARGET_OBJECTS`` for the paper's
            targets, the position in ``target_objects`` for another YCB set, the BOP id for BOP-model
            targets; BOP: its id).
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
        rgb: (H, W, 3) uint8, or ``None`` when loaded with ``rgb=False``.
        depth: (H, W) float32 depth along the optical axis in metres, 0.0 where there is no
            measurement; ``None`` if the split has no depth or it was loaded with ``depth=False``.
        K: (3, 3) float64 camera intrinsics (pixel-centre convention: pixel (u, v) has its centre at
            integer coordinates, so ``p = K @ p_C / z`` gives the pixel index directly).
        instances: annotated instances.
    """

    scene_id: int
    im_id: int
    rgb: np.ndarray | None
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
        mesh: ``(vertices (V, 3) float64 metres, faces (F, 3) int64)`` when the model file is a mesh,
            else ``None`` (synthetic reference clouds are point clouds).
        symmetries: the object's symmetry annotation in the BOP ``models_info.json`` form
            (``{"symmetries_discrete": [...], "symmetries_continuous": [...], "diameter": mm}``,
            millimetres), or ``None`` if the dataset has none (see
            :func:`sixdpose.evaluation.metrics.symmetry_transformations`).
    """

    obj_name: str
    obj_id: int
    points: np.ndarray
    normals: np.ndarray | None
    colors: np.ndarray | None
    diameter: float
    symmetric: bool
    mesh: tuple[np.ndarray, np.ndarray] | None = None
    symmetries: dict | None = None


@runtime_checkable
class DatasetReader(Protocol):
    """What every later stage needs of a dataset; :func:`open_dataset` returns one.

    Implemented by :class:`~sixdpose.datasets.synthetic.SyntheticDataset` (the paper's layout) and
    :class:`~sixdpose.datasets.bop.BopDataset`. A reader is also a ``torch`` map-style dataset
    (``len(reader)``, ``reader[i]`` = ``reader.load(reader.keys()[i])``).

    Attributes:
        location: the directory that holds the images (synthetic: the dataset root; BOP: the split
            folder), for messages.
        has_depth: every image has a depth map. has_masks: every instance has a visible mask.
        manifest: how the data was made (the generator's ``manifest.json``), ``{}`` if unknown.
    """

    location: Path
    has_depth: bool
    has_masks: bool
    manifest: dict

    def __len__(self) -> int:
        """Number of images."""

    def __getitem__(self, index: int) -> Sample:
        """The ``index``-th image with everything loaded."""

    def keys(self) -> list[Key]:
        """``(scene_id, im_id)`` of every image in order (a cached list: do not modify it)."""

    def load(self, key: Key, *, masks: bool = True, rgb: bool = True, depth: bool = True) -> Sample:
        """Read one image; ``masks``/``rgb``/``depth`` False skip those files (the field is ``None``)."""

    def model(self, obj_id: int) -> ObjectModel:
        """The reference model of ``obj_id`` (cached)."""

    @property
    def object_ids(self) -> dict[int, str]:
        """obj_id -> object name of every model of the dataset."""


class KeyedImages:
    """The ``torch`` map-style dataset part of a :class:`DatasetReader` that lists its images in
    ``self._keys`` (``(scene_id, im_id)``, in order) and reads one with ``self.load``; ``reader[i]``
    reads the instance masks when ``self.load_masks`` is true."""

    _keys: list[Key]
    load_masks: bool
    load: Callable[..., Sample]  # the reader's DatasetReader.load

    def __len__(self) -> int:
        return len(self._keys)

    def __getitem__(self, index: int) -> Sample:
        return self.load(self._keys[index], masks=self.load_masks)

    def keys(self) -> list[Key]:
        """``(scene_id, im_id)`` of every image, in order (cached; do not modify)."""
        return self._keys


def collate_samples(batch: list[Sample]) -> list[Sample]:
    """``collate_fn`` for ``torch.utils.data.DataLoader``: keep samples as a list."""
    return list(batch)


def read_image(path: str | Path, modes: tuple[str, ...] | None = None, expected: str = "") -> np.ndarray:
    """Read an image file (PNG, JPEG, 16-bit PNG) into a numpy array; with ``modes``, its PIL mode must be
    one of them.

    Raises:
        DatasetError: naming the file, if it is missing or not a readable image, or (with ``modes``) naming
            its mode and ``expected``.
    """
    from PIL import Image

    try:
        with Image.open(path) as im:
            if modes is not None and im.mode not in modes:
                raise DatasetError(f"{path}: expected {expected}, got an image of mode {im.mode} "
                                   f"({len(im.getbands())} channel(s))")
            return np.asarray(im).copy()
    except DatasetError:
        raise
    except FileNotFoundError:
        raise DatasetError(f"{path}: file not found") from None
    except Exception as e:  # PIL raises several types for truncated / non-image files
        raise DatasetError(f"{path}: unreadable image ({e})") from None


def read_rgb(path: str | Path, grey: bool = True) -> np.ndarray:
    """Read an 8-bit colour image: (H, W, 3) uint8. RGBA drops alpha; 8-bit grey (``L``, accepted when
    ``grey``) is repeated to 3 channels.

    Raises:
        DatasetError: missing, unreadable, or not 8-bit RGB/RGBA(/grey) (e.g. a 16-bit or palette image).
    """
    a = read_image(path, ("RGB", "RGBA", "L") if grey else ("RGB", "RGBA"), "an 8-bit RGB image")
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=2)
    return np.ascontiguousarray(a[..., :3])


def read_depth_png16(path: str | Path) -> np.ndarray:
    """Read a 16-bit single-channel depth PNG (BOP): (H, W) uint16 raw units.

    Raises:
        DatasetError: missing, unreadable, or not 16-bit single-channel (an 8-bit or colour image
            would be read at the wrong scale, so it is refused).
    """
    a = read_image(path, ("I;16", "I;16B", "I;16L"), "a 16-bit single-channel depth image")
    if a.ndim != 2:
        raise DatasetError(f"{path}: expected a 16-bit single-channel depth image, got shape {a.shape}")
    return a.astype(np.uint16, copy=False)


def read_mask(path: str | Path) -> np.ndarray:
    """Read a binary mask image (8-bit grey or 1-bit; value > 0 is inside): (H, W) bool.

    Raises:
        DatasetError: missing, unreadable, or not an 8-bit/1-bit single-channel image.
    """
    a = read_image(path, ("L", "1"), "an 8-bit single-channel mask")
    return a > 0


def check_depth_scale(reader: DatasetReader, n_images: int = 3, low: float = 0.5, high: float = 2.0) -> float | None:
    """Guard against a wrong depth unit: compare the median masked depth of annotated instances with
    their ground-truth distance ``t_z`` on the first ``n_images`` images that have both.

    A correct depth map puts an object's visible surface a little in front of its origin (ratio about
    0.8-1.05); a millimetre/metre mix-up or a wrong BOP ``depth_scale`` is off by a factor of 10 or more.

    Returns:
        the median ratio, or ``None`` when no image has depth, masks and poses to compare.
    Raises:
        DatasetError: the ratio lies outside ``[low, high]``.
    """
    ratios, seen = [], 0
    for key in reader.keys()[:50]:
        try:
            s = reader.load(key, rgb=False)
        except DatasetError:
            continue
        if s.depth is None:
            return None
        before = len(ratios)
        for inst in s.instances:
            if inst.mask is None or inst.t[2] <= 0 or inst.mask.shape != s.depth.shape:
                continue
            d = s.depth[inst.mask]
            d = d[np.isfinite(d) & (d > 0)]
            if len(d) >= 20:
                ratios.append(float(np.median(d)) / float(inst.t[2]))
        seen += len(ratios) > before
        if seen >= n_images:
            break
    if not ratios:
        return None
    r = float(np.median(ratios))
    if not low <= r <= high:
        raise DatasetError(
            f"{reader.location}: depth looks wrongly scaled: the masked depth is {r:.3g} x the ground-truth "
            "distance of the objects (check the depth unit: metres in the synthetic layout, "
            "depth_scale in BOP scene_camera.json)"
        )
    return r
