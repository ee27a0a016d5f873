"""Reader for the paper's synthetic layout (section III-C; file names and encodings in
:mod:`sixdpose.datasets.layout`), as written by ``sixdpose generate``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from . import layout
from .base import DatasetError, Instance, ObjectModel, Sample, read_image
from .ply import read_ply

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
    """The synthetic dataset, a :class:`~sixdpose.datasets.base.DatasetReader` (and a ``torch`` Dataset).

    Args:
        root: dataset directory.
        image_ids: optional subset of image numbers (default: all images in ``gt.yml``).
        load_masks: whether ``reader[i]`` reads the per-instance mask PNGs (default True).
    """

    has_depth = True
    has_masks = True

    def __init__(self, root: str | Path, image_ids=None, load_masks: bool = True):
        self.root = Path(root)
        if not self.root.is_dir():
            raise DatasetError(f"{self.root}: dataset directory not found")
        gt_path = self.root / layout.GT_FILE
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
        try:
            self._keys: list[tuple[int, int]] = [(int(self.gt[i]["scene_id"]), i) for i in ids]
        except (KeyError, TypeError, ValueError) as e:
            raise DatasetError(f"{gt_path}: an image entry has no valid scene_id ({e})") from None
        self.load_masks = load_masks
        manifest = self.root / layout.MANIFEST_FILE
        self.manifest = json.loads(manifest.read_text()) if manifest.is_file() else {}
        self._models: dict[int, ObjectModel] = {}
        self._info = None

    @property
    def location(self) -> Path:
        """The dataset directory (where the images are)."""
        return self.root

    # -- torch Dataset protocol -------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.image_ids)

    def __getitem__(self, index: int) -> Sample:
        return self.load(self._keys[index], masks=self.load_masks)

    def keys(self) -> list[tuple[int, int]]:
        """``(scene_id, im_id)`` of every image, in order (cached; do not modify)."""
        return self._keys

    # -- reading ----------------------------------------------------------------------------
    def load(self, key: tuple[int, int], *, masks: bool = True, rgb: bool = True, depth: bool = True) -> Sample:
        """Read image ``key = (scene_id, im_id)``: RGB, depth (metres), K and its annotated instances.

        ``masks``/``rgb``/``depth`` False skip reading those files (the fields are ``None``).
        """
        try:
            scene_id, im_id = (int(v) for v in key)
        except (TypeError, ValueError):
            raise DatasetError(f"{self.root}: image key must be (scene_id, im_id), got {key!r}") from None
        if im_id not in self.gt or int(self.gt[im_id].get("scene_id", -1)) != scene_id:
            raise DatasetError(f"{self.root / 'gt.yml'}: no image {im_id} in scene {scene_id}")
        entry = self.gt[im_id]
        rgb_im = None
        if rgb:
            rgb_im = read_image(self.root / layout.rgb_file(im_id))
            if rgb_im.ndim != 3:
                raise DatasetError(f"{self.root / layout.rgb_file(im_id)}: expected an RGB image")
            rgb_im = rgb_im[..., :3]
        depth_im = None
        if depth:
            dpath = self.root / layout.depth_file(im_id)
            try:
                depth_im = np.load(dpath).astype(np.float32, copy=False)
            except FileNotFoundError:
                raise DatasetError(f"{dpath}: file not found") from None
            except Exception as e:
                raise DatasetError(f"{dpath}: unreadable depth ({e})") from None
            if depth_im.ndim != 2 or (rgb_im is not None and depth_im.shape != rgb_im.shape[:2]):
                raise DatasetError(f"{dpath}: shape {depth_im.shape} does not match the RGB image "
                                   f"{None if rgb_im is None else rgb_im.shape[:2]}")
        try:
            K = np.asarray(entry["cam_K"], dtype=np.float64).reshape(3, 3)
        except (KeyError, ValueError) as e:
            raise DatasetError(f"{self.root / 'gt.yml'}: image {im_id}: bad cam_K ({e})") from None
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
                m = read_image(self.root / layout.mask_file(name, im_id, inst.inst))
                inst.mask = m > 0 if m.ndim == 2 else m[..., 0] > 0
            insts.append(inst)
        return Sample(scene_id, im_id, rgb_im, depth_im, K, insts)

    def merged_mask(self, im_id: int) -> np.ndarray:
        """The paper's merged mask of image ``im_id`` (uint8, value = code - instance)."""
        return read_image(self.root / layout.merged_mask_file(im_id))

    # -- models -----------------------------------------------------------------------------
    @property
    def models_info(self) -> dict:
        """``models/models_info.yml`` as a dict keyed by object name."""
        if self._info is None:
            self._info = load_yaml(self.root / layout.MODELS_INFO_FILE) or {}
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
            ply = read_ply(self.root / layout.model_file(name))
            mesh = (ply.vertices, ply.faces) if ply.faces is not None and len(ply.faces) else None
            self._models[obj_id] = ObjectModel(name, obj_id, ply.vertices, ply.normals, ply.colors, float(info["diameter"]),
                                               bool(info.get("symmetric", False)), mesh=mesh)
        return self._models[obj_id]
