"""Writing the paper's layout (section III-C) safely.

Every scene is rendered into ``D/.partial/scene_<s>/`` and then moved file by file into the dataset
with ``os.replace``; the scene's record ``D/.scenes/<s>.json`` is written last (atomically) and is the
commit point. ``gt.yml`` and ``manifest.json`` are rebuilt from the committed records only, so an
interrupted scene is never part of the dataset, and a re-run redoes exactly the uncommitted scenes.
"""

from __future__ import annotations

import io
import json
import os
import shutil
from pathlib import Path

import numpy as np
import yaml

from ..constants import MERGED_MASK_CODES, YCB_ATTRIBUTION

try:
    _Dumper = yaml.CSafeDumper
except AttributeError:  # pragma: no cover
    _Dumper = yaml.SafeDumper

RECORDS = ".scenes"
PARTIAL = ".partial"


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and ``os.replace`` (never half-written)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with open(tmp, "wb") as f:
        f.write(data)
    os.replace(tmp, path)


def atomic_write_text(path: Path, text: str) -> None:
    """Text version of :func:`atomic_write_bytes` (UTF-8)."""
    atomic_write_bytes(path, text.encode())


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


def write_ply(path: Path, points: np.ndarray, normals: np.ndarray, colors: np.ndarray) -> None:
    """Write a binary little-endian PLY point cloud with float32 x,y,z,nx,ny,nz and uchar RGB.

    Args:
        points, normals: (N, 3); colors: (N, 3) floats in [0, 1].
    """
    n = len(points)
    dt = np.dtype([("p", "<f4", 3), ("n", "<f4", 3), ("c", "u1", 3)])
    arr = np.empty(n, dtype=dt)
    arr["p"], arr["n"] = points, normals
    arr["c"] = np.clip(np.round(colors * 255), 0, 255)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment sixdpose reference model, metres\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
    )
    atomic_write_bytes(path, header.encode() + arr.tobytes())


def yaml_text(obj) -> str:
    """Deterministic YAML text (libyaml when available)."""
    return yaml.dump(obj, Dumper=_Dumper, sort_keys=True, default_flow_style=None, width=1000)


def scene_files(views: dict) -> dict[str, bytes]:
    """Encode one scene's rendered views into ``{relative path: bytes}`` of the layout.

    Args:
        views: im_id -> dict with ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 metres,
            ``instances``: list of (obj_name, inst, mask (H, W) bool).
    """
    files: dict[str, bytes] = {}
    for im_id, v in views.items():
        files[f"RGB/{im_id}.png"] = png_bytes(v["rgb"])
        files[f"depth/{im_id}.npy"] = npy_bytes(v["depth"].astype(np.float32))
        merged = np.zeros(v["depth"].shape, np.uint8)
        for name, inst, mask in v["instances"]:
            files[f"masks/{name}/{im_id}_{inst}.png"] = png_bytes(mask.astype(np.uint8) * 255)
            merged[mask] = MERGED_MASK_CODES[name] - inst
        files[f"merged_masks/{im_id}.png"] = png_bytes(merged)
    return files


def commit_scene(root: Path, scene: int, files: dict[str, bytes], record: dict) -> None:
    """Stage ``files`` under ``.partial``, move them into the dataset, then write the record."""
    stage = root / PARTIAL / f"scene_{scene:06d}"
    if stage.exists():
        shutil.rmtree(stage)
    for rel, data in files.items():
        p = stage / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)
    for rel in files:
        dst = root / rel
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.replace(stage / rel, dst)
    shutil.rmtree(stage, ignore_errors=True)
    atomic_write_text(root / RECORDS / f"{scene:06d}.json", json.dumps(record, sort_keys=True))


def read_records(root: Path) -> dict[int, dict]:
    """The committed scene records of a dataset, by scene index (corrupt records are ignored, so
    their scenes are regenerated)."""
    out = {}
    d = root / RECORDS
    if d.is_dir():
        for p in sorted(d.glob("*.json")):
            try:
                rec = json.loads(p.read_text())
                out[int(rec["scene"])] = rec
            except (ValueError, KeyError):
                continue
    return out


def write_attribution(root: Path, assets_dir: Path) -> None:
    """Write ``ATTRIBUTION.txt`` and copy the YCB licence text if the asset directory has one."""
    atomic_write_text(root / "ATTRIBUTION.txt", YCB_ATTRIBUTION + "\n")
    lic = assets_dir / "LICENSE-CC-BY-4.0.txt"
    if lic.is_file():
        atomic_write_bytes(root / "LICENSE-CC-BY-4.0.txt", lic.read_bytes())


def finalize(root: Path, records: dict[int, dict], manifest_head: dict) -> dict:
    """Rebuild ``gt.yml`` and ``manifest.json`` from the committed ``records``.

    Returns:
        the manifest dict.
    """
    gt: dict[int, dict] = {}
    scenes = {}
    for s in sorted(records):
        rec = records[s]
        for im in rec["images"]:
            gt[int(im["im_id"])] = {
                "scene_id": s,
                "cam_K": im["cam_K"],
                "cam_R_WC": im["cam_R_WC"],
                "cam_t_WC": im["cam_t_WC"],
                "objects": im["objects"],
            }
        scenes[str(s)] = {
            "images": [rec["image_range"][0], rec["image_range"][1]],
            "attempt": rec["attempt"],
            "sim_time": rec["sim_time"],
            "objects": rec["objects"],
        }
    atomic_write_text(root / "gt.yml", yaml_text(gt))
    manifest = dict(manifest_head)
    manifest["scenes"] = scenes
    manifest["num_images"] = len(gt)
    atomic_write_text(root / "manifest.json", json.dumps(manifest, indent=1, sort_keys=True))
    return manifest
