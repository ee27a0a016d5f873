"""Reader for the paper's synthetic layout (section III-C; file names and encodings in
:mod:`sixdpose.datasets.layout`), as written by ``sixdpose generate``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from .. import schemas
from . import layout
from .base import DatasetError, Instance, KeyedImages, ObjectModel, Sample, read_image, read_mask, read_rgb
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
    except (OSError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: unreadable ({e})") from None


def load_manifest(path: Path) -> dict:
    """Read ``manifest.json`` (``{}`` if absent); a corrupt or truncated file is a :class:`DatasetError`."""
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: corrupt JSON ({e})") from None
    return schemas.check(schemas.SYN_MANIFEST, data, path, DatasetError)


class SyntheticDataset(KeyedImages):
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
        schemas.check(schemas.SYN_GT, gt, gt_path, DatasetError, item="image")  # each image in full when read
        self.gt: dict[int, dict] = dict(gt)
        ids = sorted(self.gt) if image_ids is None else [int(i) for i in image_ids]
        missing = [i for i in ids if i not in self.gt]
        if missing:
            raise DatasetError(f"{gt_path}: no entry for image(s) {missing[:5]}")
        self.image_ids = ids
        self._keys: list[tuple[int, int]] = [(int(self.gt[i]["scene_id"]), i) for i in ids]
        self.load_masks = load_masks
        self.manifest = load_manifest(self.root / layout.MANIFEST_FILE)
        self._models: dict[int, ObjectModel] = {}
        self._info = None
        self._entries: dict[int, schemas.SynImage] = {}

    @property
    def location(self) -> Path:
        """The dataset directory (where the images are)."""
        return self.root

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
        entry = self._entry(im_id)
        rgb_im = None
        if rgb:
            rgb_im = read_rgb(self.root / layout.rgb_file(im_id), grey=False)
        depth_im = None
        if depth:
            dpath = self.root / layout.depth_file(im_id)
            try:
                raw = np.load(dpath, allow_pickle=False)
            except FileNotFoundError:
                raise DatasetError(f"{dpath}: file not found") from None
            except Exception as e:
                raise DatasetError(f"{dpath}: unreadable depth ({e})") from None
            if not np.issubdtype(raw.dtype, np.floating):
                raise DatasetError(f"{dpath}: expected float depth in metres, got dtype {raw.dtype} "
                                   "(integer depth would be read at the wrong scale)")
            depth_im = raw.astype(np.float32, copy=False)
            if depth_im.ndim != 2 or (rgb_im is not None and depth_im.shape != rgb_im.shape[:2]):
                raise DatasetError(f"{dpath}: shape {depth_im.shape} does not match the RGB image "
                                   f"{None if rgb_im is None else rgb_im.shape[:2]}")
        K = np.asarray(entry.cam_K, dtype=np.float64).reshape(3, 3)
        insts = []
        for o in entry.objects or []:
            inst = Instance(obj_name=o.obj_name, obj_id=o.obj_id, inst=o.inst, R=np.asarray(o.R, dtype=np.float64),
                            t=np.asarray(o.t, dtype=np.float64), px_visib=o.px_visib)
            if masks:
                inst.mask = read_mask(self.root / layout.mask_file(o.obj_name, im_id, inst.inst))
            insts.append(inst)
        return Sample(scene_id, im_id, rgb_im, depth_im, K, insts)

    def _entry(self, im_id: int) -> schemas.SynImage:
        """The ``gt.yml`` entry of image ``im_id``, validated (:class:`sixdpose.schemas.SynImage`; cached).

        Raises:
            DatasetError: naming ``gt.yml``, the image and the field.
        """
        if im_id not in self._entries:
            self._entries[im_id] = schemas.check(schemas.SYN_IMAGE, self.gt[im_id], self.root / layout.GT_FILE,
                                                 DatasetError, f"image {im_id}: ")
        return self._entries[im_id]

    def merged_mask(self, im_id: int) -> np.ndarray:
        """The paper's merged mask of image ``im_id`` (uint8, value = code - instance)."""
        return read_image(self.root / layout.merged_mask_file(im_id))

    # -- models -----------------------------------------------------------------------------
    @property
    def models_info(self) -> dict:
        """``models/models_info.yml`` as a dict keyed by object name."""
        if self._info is None:
            path = self.root / layout.MODELS_INFO_FILE
            info = load_yaml(path) or {}
            schemas.check(schemas.SYN_MODELS_INFO, info, path, DatasetError, item="object")
            self._info = info
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
            self._models[obj_id] = ObjectModel(name, obj_id, ply.vertices, ply.normals, ply.colors,
                                               float(info["diameter"]), bool(info.get("symmetric", False)), mesh=mesh)
        return self._models[obj_id]
