"""Writing the paper's layout (section III-C) safely.

Every scene is rendered into ``D/.partial/scene_<s>/`` and then moved file by file into the dataset
with ``os.replace``; the scene's record ``D/.scenes/<s>.json`` is written last (atomically) and is the
commit point. ``gt.yml`` and ``manifest.json`` are rebuilt from the committed records only, so an
interrupted scene is never part of the dataset, and a re-run redoes exactly the uncommitted scenes.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from ..constants import YCB_ATTRIBUTION
from ..datasets.layout import image_files, write_gt, write_manifest
from ..fileio import atomic_write_text, write_if_changed

RECORDS = ".scenes"
PARTIAL = ".partial"


def scene_files(views: dict, codes: dict[str, int] | None = None) -> dict[str, bytes]:
    """Encode one scene's rendered views into ``{relative path: bytes}`` of the layout
    (:func:`sixdpose.datasets.layout.image_files`).

    Args:
        views: im_id -> dict with ``rgb`` (H, W, 3) uint8, ``depth`` (H, W) float32 metres,
            ``instances``: list of (obj_name, inst, mask (H, W) bool).
        codes: target name -> merged-mask code (default: the paper's).
    """
    files: dict[str, bytes] = {}
    for im_id, v in views.items():
        files.update(image_files(im_id, v["rgb"], v["depth"], v["instances"], codes))
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
    write_if_changed(root / "ATTRIBUTION.txt", YCB_ATTRIBUTION + "\n")
    lic = assets_dir / "LICENSE-CC-BY-4.0.txt"
    if lic.is_file():
        write_if_changed(root / "LICENSE-CC-BY-4.0.txt", lic.read_bytes())


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
    write_gt(root, gt)
    manifest = dict(manifest_head)
    manifest["scenes"] = scenes
    manifest["num_images"] = len(gt)
    write_manifest(root, manifest)
    return manifest
