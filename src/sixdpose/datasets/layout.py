"""The paper's synthetic dataset layout (section III-C): the one place that knows its file names and
encodings. The generator, the toy data of the segmentation tests and the test fixtures write through
it; :class:`~sixdpose.datasets.synthetic.SyntheticDataset` reads it.

Layout of a dataset directory ``D``::

    D/RGB/#.png                      640x480 RGB (uint8)
    D/depth/#.npy                    float32 depth in metres, 0.0 where no surface is within range
    D/masks/<object>/#_<inst>.png    binary visible mask (0/255) of one target instance
    D/merged_masks/#.png             uint8, value = code(object) - instance (paper codes; other target
                                     sets: sixdpose.constants.merged_mask_codes)
    D/models/<object>.ply            coloured reference point cloud (metres, with normals)
    D/models/models_info.yml         per object: obj_id, diameter, bounding box, symmetric, mask_code,
                                     source (ycb or the BOP model file) and source_sha256 (BOP)
    D/gt.yml                         per image: scene_id, cam_K and, per visible target instance,
                                     obj_name, obj_id, inst, R (3x3, X_CO), t (metres), px_visib
    D/manifest.json                  who wrote it (generator, version, config, scenes ...)

``#`` is the global image number. Encodings are deterministic (same arrays -> same bytes).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import yaml

from ..constants import MERGED_MASK_CODES
from ..fileio import atomic_write_bytes, atomic_write_text, write_if_changed

try:
    _Dumper = yaml.CSafeDumper
except AttributeError:  # pragma: no cover
    _Dumper = yaml.SafeDumper

GT_FILE = "gt.yml"
MODELS_INFO_FILE = "models/models_info.yml"
MANIFEST_FILE = "manifest.json"


# -- relative paths ------------------------------------------------------------------------------
def rgb_file(im_id: int) -> str:
    """Relative path of the RGB image ``im_id``."""
    return f"RGB/{int(im_id)}.png"


def depth_file(im_id: int) -> str:
    """Relative path of the depth map ``im_id`` (float32 metres, ``.npy``)."""
    return f"depth/{int(im_id)}.npy"


def mask_file(obj_name: str, im_id: int, inst: int) -> str:
    """Relative path of the visible mask of instance ``inst`` of ``obj_name`` in image ``im_id``."""
    return f"masks/{obj_name}/{int(im_id)}_{int(inst)}.png"


def merged_mask_file(im_id: int) -> str:
    """Relative path of the merged mask of image ``im_id``."""
    return f"merged_masks/{int(im_id)}.png"


def model_file(obj_name: str) -> str:
    """Relative path of the reference model of ``obj_name``."""
    return f"models/{obj_name}.ply"


# -- encodings -----------------------------------------------------------------------------------
def png_bytes(img: np.ndarray) -> bytes:
    """Encode a uint8 image (H, W) or (H, W, 3) as PNG (deterministic bytes)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def npy_bytes(arr: np.ndarray) -> bytes:
    """Encode an array in ``.npy`` format."""
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def yaml_text(obj) -> str:
    """Deterministic YAML text (libyaml when available)."""
    return yaml.dump(obj, Dumper=_Dumper, sort_keys=True, default_flow_style=None, width=1000)


def merged_mask(shape: tuple[int, int], instances, codes: dict[str, int] = MERGED_MASK_CODES) -> np.ndarray:
    """The paper's merged mask: uint8 ``code(object) - inst`` on each instance's visible pixels.

    Args:
        shape: (H, W). instances: iterable of ``(obj_name, inst, mask (H, W) bool)``.
        codes: object name -> code (the paper's for its 18 targets).
    """
    merged = np.zeros(shape, np.uint8)
    for name, inst, mask in instances:
        merged[mask] = codes[name] - inst
    return merged


def image_files(im_id: int, rgb: np.ndarray, depth: np.ndarray, instances,
                codes: dict[str, int] | None = None) -> dict[str, bytes]:
    """Encode one image into ``{relative path: bytes}`` of the layout.

    Args:
        im_id: global image number. rgb: (H, W, 3) uint8. depth: (H, W) metres.
        instances: list of ``(obj_name, inst, mask (H, W) bool)`` of the visible target instances.
        codes: object name -> merged-mask code (default: the paper's codes of its 18 targets; other
            target sets: :func:`sixdpose.constants.merged_mask_codes`).
    """
    files = {rgb_file(im_id): png_bytes(rgb), depth_file(im_id): npy_bytes(np.asarray(depth).astype(np.float32))}
    for name, inst, mask in instances:
        files[mask_file(name, im_id, inst)] = png_bytes(mask.astype(np.uint8) * 255)
    files[merged_mask_file(im_id)] = png_bytes(
        merged_mask(np.asarray(depth).shape, instances, MERGED_MASK_CODES if codes is None else codes))
    return files


def object_entry(obj_name: str, obj_id: int, inst: int, R: np.ndarray, t: np.ndarray, px_visib: int) -> dict:
    """The ``gt.yml`` entry of one instance (``R``, ``t``: ``X_CO``, metres)."""
    return {"obj_name": obj_name, "obj_id": int(obj_id), "inst": int(inst),
            "R": np.asarray(R, float).reshape(3, 3).tolist(),
            "t": np.asarray(t, float).reshape(3).tolist(), "px_visib": int(px_visib)}


# -- whole files ---------------------------------------------------------------------------------
def write_gt(root: str | Path, gt: dict[int, dict]) -> Path:
    """Write ``gt.yml`` (image number -> ``{scene_id, cam_K, objects, ...}``) atomically (left untouched
    when it already holds the same text)."""
    path = Path(root) / GT_FILE
    write_if_changed(path, yaml_text(gt))
    return path


def write_models_info(root: str | Path, info: dict[str, dict]) -> Path:
    """Write ``models/models_info.yml`` (object name -> ``{obj_id, diameter, symmetric, ...}``) atomically."""
    return atomic_write_text(Path(root) / MODELS_INFO_FILE, yaml_text(info))


def write_manifest(root: str | Path, manifest: dict) -> Path:
    """Write ``manifest.json`` atomically (sorted keys; left untouched when it already holds the same
    text, so resuming a complete dataset does not make everything that depends on it out of date)."""
    path = Path(root) / MANIFEST_FILE
    write_if_changed(path, json.dumps(manifest, indent=1, sort_keys=True))
    return path


def write_files(root: str | Path, files: dict[str, bytes]) -> None:
    """Write ``{relative path: bytes}`` under ``root``, each file atomically."""
    root = Path(root)
    for rel, data in files.items():
        atomic_write_bytes(root / rel, data)


def write_dataset(root: str | Path, images, models: dict[str, dict], manifest: dict) -> Path:
    """Write a small dataset in one go (test fixtures, toy data); the generator stages scenes itself.

    Args:
        root: output directory.
        images: iterable of dicts with ``im_id``, ``scene_id``, ``K`` (3, 3), ``rgb`` (H, W, 3) uint8,
            ``depth`` (H, W) metres and ``instances``: list of dicts with ``obj_name``, ``obj_id``,
            ``inst``, ``R``, ``t`` (metres), ``mask`` (H, W) bool.
        models: object name -> ``{"obj_id", "diameter", "symmetric", "points", "normals", "colors"}``
            (``points`` etc. optional: a model without points gets no PLY file).
        manifest: written as ``manifest.json`` (say who wrote the data).
    Returns:
        ``root``.
    """
    from .ply import write_ply

    root = Path(root)
    gt = {}
    for im in images:
        insts = im["instances"]
        write_files(root, image_files(im["im_id"], im["rgb"], im["depth"],
                                      [(i["obj_name"], i["inst"], i["mask"]) for i in insts]))
        gt[int(im["im_id"])] = {
            "scene_id": int(im["scene_id"]),
            "cam_K": np.asarray(im["K"], float).reshape(3, 3).tolist(),
            "objects": [object_entry(i["obj_name"], i["obj_id"], i["inst"], i["R"], i["t"],
                                     int(np.count_nonzero(i["mask"])))
                        for i in insts],
        }
    info = {}
    for name, m in models.items():
        info[name] = {"obj_id": int(m["obj_id"]), "diameter": float(m["diameter"]),
                      "symmetric": bool(m.get("symmetric", False))}
        if m.get("points") is not None:
            write_ply(root / model_file(name), m["points"], m.get("normals"), m.get("colors"))
    write_models_info(root, info)
    write_gt(root, gt)
    write_manifest(root, manifest)
    return root
