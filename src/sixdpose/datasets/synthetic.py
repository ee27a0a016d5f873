"""Reader for the paper's synthetic layout (section III-C), as written by ``sixdpose generate``.

Layout of a dataset directory ``D``::

    D/RGB/#.png                      640x480 RGB
    D/depth/#.npy                    float32 depth in metres, 0.0 where no surface is within range
    D/masks/<object>/#_<inst>.png    binary visible mask (0/255) of one target instance
    D/merged_masks/#.png             uint8, value = code(object) - instance (paper codes)
    D/models/<object>.ply            coloured reference point cloud (metres, with normals)
    D/models/models_info.yml         diameter and bounding box (min_x.., size_x..) per target
    D/gt.yml                         per image: cam_K and, per visible target instance,
                                     obj_name, obj_id, inst, R (3x3, X_CO), t (metres), px_visib
    D/manifest.json                  generator version, config, seed, per-scene objects and images
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from .base import DatasetError, Instance, ObjectModel, Sample, read_image, read_ply

try:  # fast YAML if libyaml is present
    _Loader = yaml.CSafeLoader
except AttributeError:  # pragma: no cover
    _Loader = yaml.SafeLoader


def load_yaml(path: Path):
    """Load a YAML file, raising :class:`DatasetError` naming the file if it is missing or corrupt."""
    if not path.is_file():
        raise DatasetError(f"{path}: file not found")
    try:
        with open(path) as f:
            return yaml.load(f, Loader=_Loader)
    except yaml.YAMLError as e:
        raise DatasetError(f"{path}: corrupt YAML ({str(e).splitlines()[0]})") from None


class SyntheticDataset:
    """The synthetic dataset as a sequence of :class:`Sample` (usable as a ``torch`` Dataset).

    Args:
        root: dataset directory.
        image_ids: optional subset of image numbers (default: all images in ``gt.yml``).
        load_masks: read the per-instance mask PNGs (default True).
    """

    def __init__(self, root: str | Path, image_ids=None, load_masks: bool = True):
        self.root = Path(root)
        if not self.root.is_dir():
            raise DatasetError(f"{self.root}: dataset directory not found")
        gt_path = self.root / "gt.yml"
        if not gt_path.is_file():
            raise DatasetError(
                f"{gt_path}: missing; the generation run did not finish (run `sixdpose generate` again "
                "with the same arguments to complete it)"
            )
        gt = load_yaml(gt_path) or {}
        if not isinstance(gt, dict):
            raise DatasetError(f"{gt_path}: expected a mapping image number -> annotations")
        self.gt: dict[int, dict] = {int(k): v for k, v in gt.items()}
        ids = sorted(self.gt) if image_ids is None else [int(i) for i in image_ids]
        missing = [i for i in ids if i not in self.gt]
        if missing:
            raise DatasetError(f"{gt_path}: no entry for image(s) {missing[:5]}")
        self.image_ids = ids
        self.load_masks = load_masks
        manifest = self.root / "manifest.json"
        self.manifest = json.loads(manifest.read_text()) if manifest.is_file() else {}
        self._models: dict[int, ObjectModel] = {}
        self._info = None

    # -- torch Dataset protocol -------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.image_ids)

    def __getitem__(self, index: int) -> Sample:
        return self.load(self.image_ids[index])

    def keys(self) -> list[tuple[int, int]]:
        """``(scene_id, im_id)`` of every image, in order."""
        return [(int(self.gt[i]["scene_id"]), i) for i in self.image_ids]

    # -- reading ----------------------------------------------------------------------------
    def load(self, im_id: int, with_masks: bool | None = None) -> Sample:
        """Read image ``im_id`` (RGB, depth, K and its annotated instances)."""
        if im_id not in self.gt:
            raise DatasetError(f"{self.root / 'gt.yml'}: no image {im_id}")
        entry = self.gt[im_id]
        rgb = read_image(self.root / "RGB" / f"{im_id}.png")
        if rgb.ndim != 3:
            raise DatasetError(f"{self.root / 'RGB' / f'{im_id}.png'}: expected an RGB image")
        rgb = rgb[..., :3]
        dpath = self.root / "depth" / f"{im_id}.npy"
        try:
            depth = np.load(dpath).astype(np.float32, copy=False)
        except FileNotFoundError:
            raise DatasetError(f"{dpath}: file not found") from None
        except Exception as e:
            raise DatasetError(f"{dpath}: unreadable depth ({e})") from None
        if depth.shape != rgb.shape[:2]:
            raise DatasetError(f"{dpath}: shape {depth.shape} does not match the RGB image {rgb.shape[:2]}")
        try:
            K = np.asarray(entry["cam_K"], dtype=np.float64).reshape(3, 3)
        except (KeyError, ValueError) as e:
            raise DatasetError(f"{self.root / 'gt.yml'}: image {im_id}: bad cam_K ({e})") from None
        masks = self.load_masks if with_masks is None else with_masks
        insts = []
        for k, o in enumerate(entry.get("objects") or []):
            try:
                name = str(o["obj_name"])
                inst = Instance(
                    obj_name=name,
                    obj_id=int(o["obj_id"]),
                    inst=int(o["inst"]),
                    R=np.asarray(o["R"], dtype=np.float64).reshape(3, 3),
                    t=np.asarray(o["t"], dtype=np.float64).reshape(3),
                    px_visib=int(o.get("px_visib", -1)),
                )
            except (KeyError, ValueError, TypeError) as e:
                raise DatasetError(f"{self.root / 'gt.yml'}: image {im_id} object {k}: bad field ({e})") from None
            if masks:
                m = read_image(self.root / "masks" / name / f"{im_id}_{inst.inst}.png")
                inst.mask = m > 0 if m.ndim == 2 else m[..., 0] > 0
            insts.append(inst)
        return Sample(int(entry["scene_id"]), im_id, rgb, depth, K, insts)

    def merged_mask(self, im_id: int) -> np.ndarray:
        """The paper's merged mask of image ``im_id`` (uint8, value = code - instance)."""
        return read_image(self.root / "merged_masks" / f"{im_id}.png")

    # -- models -----------------------------------------------------------------------------
    @property
    def models_info(self) -> dict:
        """``models/models_info.yml`` as a dict keyed by object name."""
        if self._info is None:
            self._info = load_yaml(self.root / "models" / "models_info.yml") or {}
        return self._info

    @property
    def object_ids(self) -> dict[int, str]:
        """Map obj_id -> object name of every model in the dataset."""
        return {int(v["obj_id"]): k for k, v in self.models_info.items()}

    def model(self, obj_id: int) -> ObjectModel:
        """The reference model (points in metres, normals, colours) of object ``obj_id`` (cached)."""
        if obj_id not in self._models:
            names = self.object_ids
            if obj_id not in names:
                raise DatasetError(f"{self.root / 'models' / 'models_info.yml'}: no object with obj_id {obj_id}")
            name = names[obj_id]
            info = self.models_info[name]
            pts, nrm, col = read_ply(self.root / "models" / f"{name}.ply")
            self._models[obj_id] = ObjectModel(
                name, obj_id, pts, nrm, col, float(info["diameter"]), bool(info.get("symmetric", False))
            )
        return self._models[obj_id]
