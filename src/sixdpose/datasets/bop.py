"""BOP datasets (https://bop.felk.cvut.cz/datasets/) behind the :mod:`.base` reader interface,
and the export of a synthetic dataset to the BOP layout (``sixdpose export-bop``).

BOP layout of a dataset root ``B``::

    B/models/obj_NNNNNN.ply          mesh in millimetres (vertex normals / colours optional)
    B/models/models_info.json        per obj_id: diameter (mm), bounding box, symmetries_discrete /
                                     symmetries_continuous (an object with either is *symmetric*)
    B/<split>/<scene:06d>/scene_gt.json       per im_id: list of {cam_R_m2c, cam_t_m2c (mm), obj_id}
    B/<split>/<scene:06d>/scene_camera.json   per im_id: cam_K, depth_scale (depth unit in mm)
    B/<split>/<scene:06d>/scene_gt_info.json  per im_id: list of {px_count_visib, ...} (optional)
    B/<split>/<scene:06d>/rgb/<im:06d>.png    (or .jpg)
    B/<split>/<scene:06d>/depth/<im:06d>.png  16-bit depth, value * depth_scale = mm (optional)
    B/<split>/<scene:06d>/mask_visib/<im:06d>_<gt:06d>.png  visible masks (optional)

Everything is converted to metres on read. A split without ``depth/`` gives ``Sample.depth=None``;
without ``mask_visib/`` every ``Instance.mask`` is ``None`` (see :attr:`BopDataset.has_depth` and
:attr:`BopDataset.has_masks`). :class:`BopDataset` is a :class:`~sixdpose.datasets.base.DatasetReader`.

Two optional keys, ignored by the bop_toolkit, make the export of a synthetic dataset round-trip
exactly: ``obj_name`` in ``models_info.json`` and ``inst`` (instance number of the object in its
scene) in each ``scene_gt.json`` entry.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import schemas
from .base import DatasetError, Instance, KeyedImages, ObjectModel, Sample, read_depth_png16, read_mask, read_rgb
from .ply import read_ply, vertex_normals

log = logging.getLogger(__name__)

_RGB_EXTS = (".png", ".jpg", ".jpeg", ".tif")


def load_json(path: Path):
    """Load a JSON file, raising :class:`DatasetError` naming the file if missing or corrupt."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: file not found")
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: corrupt JSON ({e})") from None


def _is_symmetric(info: dict) -> bool:
    return bool(info.get("symmetries_discrete")) or bool(info.get("symmetries_continuous"))


@dataclass(frozen=True)
class BopCamera:
    """Intrinsics of a BOP camera file: ``fx, fy, cx, cy`` in pixels (integer pixel-centre
    convention, as ``cam_K``), ``width, height`` in pixels or None where the file does not say."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int | None
    height: int | None


def load_bop_camera(path: str | Path) -> BopCamera:
    """Read the camera of a BOP ``camera.json`` (``fx fy cx cy width height``, or a ``cam_K``) or of a
    ``scene_camera.json`` (per image ``cam_K``; the lowest image id's is used, and a warning is logged if
    other images have another K).

    ``scene_camera.json`` has no image size; it is taken from the first image in ``rgb/`` (or
    ``gray/``) beside the file when there is one, else left None.

    Raises:
        DatasetError: one line naming the file: missing, corrupt, no ``cam_K`` (nor ``fx, fy, cx,
            cy``), or a ``cam_K`` that is not 9 numbers.
    """
    path = Path(path)
    d = load_json(path)
    if not isinstance(d, dict):
        raise DatasetError(f"{path}: expected a JSON object")

    def k_of(entry, where):
        if not isinstance(entry.get("cam_K"), list) or len(entry["cam_K"]) != 9:
            raise DatasetError(f"{path}: {where}cam_K is not 9 numbers")
        K = schemas.check(schemas.BopCameraEntry, {"cam_K": entry["cam_K"]}, path, DatasetError, where).cam_K
        return float(K[0]), float(K[4]), float(K[2]), float(K[5])

    size = (None, None)
    if "cam_K" in d:
        schemas.check(schemas.BopCameraFile, d, path, DatasetError)
        fx, fy, cx, cy = k_of(d, "")
    elif all(k in d for k in ("fx", "fy", "cx", "cy")):
        c = schemas.check(schemas.BopCameraFile, d, path, DatasetError)
        fx, fy, cx, cy = c.fx, c.fy, c.cx, c.cy
    else:
        entries = {}
        for key, v in d.items():
            if isinstance(v, dict) and str(key).isdigit():
                entries[int(key)] = v
        with_k = {k: v for k, v in entries.items() if "cam_K" in v}
        if not with_k:
            raise DatasetError(f"{path}: no cam_K (a camera.json needs fx, fy, cx, cy or cam_K; a scene_camera.json "
                               "a cam_K per image)")
        first = min(with_k)
        fx, fy, cx, cy = k_of(with_k[first], f"image {first}: ")
        others = {k_of(v, f"image {k}: ") for k, v in with_k.items()} - {(fx, fy, cx, cy)}
        if others:
            log.warning("%s: images have %d different cam_K; using image %d's", path, len(others) + 1, first)
        for sub in ("rgb", "gray"):
            imgs = sorted((path.parent / sub).glob("*")) if (path.parent / sub).is_dir() else []
            if imgs:
                from PIL import Image

                try:
                    with Image.open(imgs[0]) as im:
                        size = im.size
                except Exception:
                    pass
                break
    if "width" in d and "height" in d:
        try:
            size = (int(d["width"]), int(d["height"]))
        except (TypeError, ValueError):
            raise DatasetError(f"{path}: width and height must be integers") from None
    if not (fx > 0 and fy > 0):
        raise DatasetError(f"{path}: focal lengths must be positive, got fx={fx}, fy={fy}")
    return BopCamera(fx, fy, cx, cy, size[0], size[1])


class BopDataset(KeyedImages):
    """One split of a BOP dataset as a sequence of :class:`Sample` (metres, ``X_CO`` poses).

    Args:
        root: BOP dataset root (contains ``models/models_info.json`` and the split folder).
        split: split folder name, e.g. ``"test"``, ``"train_real"``.
        scene_ids: optional subset of scene ids (default: every scene folder of the split).
        load_masks: read ``mask_visib`` PNGs when the split has them (default True).
        models_dir: models folder name (``"models"``; ``"models_eval"`` for the BOP eval models).
        symmetric_ids: optional override of the set of symmetric object ids (e.g. for a dataset
            distributed without symmetry annotations); default: from ``models_info.json``.
        targets: optional list of ``(scene_id, im_id)`` to restrict the images to.
    """

    def __init__(
        self,
        root: str | Path,
        split: str = "test",
        scene_ids=None,
        load_masks: bool = True,
        models_dir: str = "models",
        symmetric_ids=None,
        targets=None,
    ):
        self.root = Path(root)
        schemas.safe_name(split, "split", DatasetError)
        schemas.safe_name(models_dir, "models_dir", DatasetError)
        self.split = split
        self.models_path = self.root / models_dir
        info_path = self.models_path / "models_info.json"
        info = load_json(info_path)
        if not isinstance(info, dict):
            raise DatasetError(f"{info_path}: expected a mapping obj_id -> info")
        schemas.check(schemas.BOP_MODELS_INFO, info, info_path, DatasetError, item="object")
        self.models_info: dict[int, dict] = {int(k): v for k, v in info.items()}
        self.symmetric_ids = None if symmetric_ids is None else {int(i) for i in symmetric_ids}
        split_dir = self.root / split
        if not split_dir.is_dir():
            avail = sorted(p.name for p in self.root.iterdir() if p.is_dir() and p.name != models_dir)
            raise DatasetError(f"{split_dir}: split {split!r} not found (available: {', '.join(avail) or 'none'})")
        self.split_dir = split_dir
        self.location = split_dir
        self.manifest: dict = {}
        dirs = sorted(p for p in split_dir.iterdir() if p.is_dir() and p.name.isdigit())
        if scene_ids is not None:
            wanted = {int(s) for s in scene_ids}
            dirs = [p for p in dirs if int(p.name) in wanted]
        if not dirs:
            raise DatasetError(f"{split_dir}: no scene folders")
        self.load_masks = load_masks
        self._scene_dirs: dict[int, Path] = {int(p.name): p for p in dirs}
        self._gt: dict[int, dict[int, list]] = {}
        self._cam: dict[int, dict[int, dict]] = {}
        self._gt_info: dict[int, dict[int, list] | None] = {}
        self._keys: list[tuple[int, int]] = []
        for sid, d in self._scene_dirs.items():
            gt = schemas.check(schemas.BOP_SCENE_GT, load_json(d / "scene_gt.json"), d / "scene_gt.json", DatasetError,
                               item="image")
            cam = schemas.check(schemas.BOP_SCENE_CAMERA, load_json(d / "scene_camera.json"), d / "scene_camera.json",
                                DatasetError, item="image")
            gi = None
            if (d / "scene_gt_info.json").is_file():
                gi = schemas.check(schemas.BOP_SCENE_GT_INFO, load_json(d / "scene_gt_info.json"),
                                   d / "scene_gt_info.json", DatasetError, item="image")
            self._gt[sid] = {int(k): v for k, v in gt.items()}
            self._cam[sid] = {int(k): v for k, v in cam.items()}
            self._gt_info[sid] = None if gi is None else {int(k): v for k, v in gi.items()}
            for im in sorted(self._gt[sid]):
                if im not in self._cam[sid]:
                    raise DatasetError(f"{d / 'scene_camera.json'}: no entry for image {im}")
                self._keys.append((sid, im))
        if targets is not None:
            tset = {(int(s), int(i)) for s, i in targets}
            self._keys = [k for k in self._keys if k in tset]
        self.has_depth = all((d / "depth").is_dir() for d in self._scene_dirs.values())
        self.has_masks = all((d / "mask_visib").is_dir() for d in self._scene_dirs.values())
        if not self.has_depth:
            log.info("%s: split %r has no depth images; Sample.depth will be None", self.root, split)
        if not self.has_masks:
            log.info("%s: split %r has no mask_visib; Instance.mask will be None", self.root, split)
        self._models: dict[int, ObjectModel] = {}
        self._checked: dict[tuple[int, int], tuple] = {}

    # -- reading ----------------------------------------------------------------------------
    def _rgb_path(self, sid: int, im: int) -> Path:
        d = self._scene_dirs[sid]
        for sub in ("rgb", "gray"):
            for ext in _RGB_EXTS:
                p = d / sub / f"{im:06d}{ext}"
                if p.is_file():
                    return p
        raise DatasetError(f"{d / 'rgb' / f'{im:06d}.png'}: file not found")

    def load(self, key: tuple[int, int], *, masks: bool = True, rgb: bool = True, depth: bool = True) -> Sample:
        """Read image ``key = (scene_id, im_id)``: RGB, depth (metres, or None when the split has none),
        K and the instances. ``masks``/``rgb``/``depth`` False skip reading those files."""
        try:
            scene_id, im_id = (int(v) for v in key)
        except (TypeError, ValueError):
            raise DatasetError(f"{self.split_dir}: image key must be (scene_id, im_id), got {key!r}") from None
        if scene_id not in self._scene_dirs:
            raise DatasetError(f"{self.split_dir}: no scene {scene_id}")
        d = self._scene_dirs[scene_id]
        if im_id not in self._gt[scene_id]:
            raise DatasetError(f"{d / 'scene_gt.json'}: no image {im_id}")
        rgb_im = None
        if rgb:
            rgb_im = read_rgb(self._rgb_path(scene_id, im_id))
        cam, gts, infos = self._frame(scene_id, im_id)
        K = np.asarray(cam.cam_K, dtype=np.float64).reshape(3, 3)
        depth_im = None
        dpath = d / "depth" / f"{im_id:06d}.png"
        if depth and (d / "depth").is_dir():
            if cam.depth_scale is None:
                raise DatasetError(f"{d / 'scene_camera.json'}: image {im_id}: missing field 'depth_scale' (the depth "
                                   "unit in mm, e.g. 0.1 for YCB-Video, 1.0 for LM-O); no default is assumed")
            raw = read_depth_png16(dpath)
            if rgb_im is not None and raw.shape != rgb_im.shape[:2]:
                raise DatasetError(f"{dpath}: shape {raw.shape} does not match the RGB image {rgb_im.shape[:2]}")
            depth_im = (raw.astype(np.float32) * np.float32(cam.depth_scale / 1000.0)).astype(np.float32)
        masks = masks and (d / "mask_visib").is_dir()
        insts = []
        seen: dict[int, int] = {}
        for k, g in enumerate(gts):
            oid = g.obj_id
            R = np.asarray(g.cam_R_m2c, dtype=np.float64).reshape(3, 3)
            t = np.asarray(g.cam_t_m2c, dtype=np.float64).reshape(3) / 1000.0
            inst = g.inst if g.inst is not None else seen.get(oid, 0)
            seen[oid] = seen.get(oid, 0) + 1
            px = -1
            if infos is not None and k < len(infos) and infos[k].px_count_visib is not None:
                px = infos[k].px_count_visib
            mask = None
            if masks:
                mask = read_mask(d / "mask_visib" / f"{im_id:06d}_{k:06d}.png")
                if px < 0:
                    px = int(mask.sum())
            name = str(self.models_info.get(oid, {}).get("obj_name", f"obj_{oid:06d}"))
            insts.append(Instance(name, oid, inst, R, t, mask, px))
        return Sample(scene_id, im_id, rgb_im, depth_im, K, insts)

    def _frame(self, scene_id: int, im_id: int) -> tuple:
        """The validated ``scene_camera``, ``scene_gt`` and ``scene_gt_info`` entries of one image (cached).

        Raises:
            DatasetError: an entry does not fit its schema (:mod:`sixdpose.schemas`): the message names
                the file, the image and the field.
        """
        key = (scene_id, im_id)
        if key not in self._checked:
            d = self._scene_dirs[scene_id]
            where = f"image {im_id}: "
            cam = schemas.check(schemas.BopCameraEntry, self._cam[scene_id][im_id], d / "scene_camera.json",
                                DatasetError, where)
            gts = schemas.check(schemas.BOP_GT_LIST, self._gt[scene_id][im_id], d / "scene_gt.json", DatasetError,
                                where, item="gt")
            infos = (self._gt_info[scene_id] or {}).get(im_id)
            if infos is not None:
                infos = schemas.check(schemas.BOP_GT_INFO_LIST, infos, d / "scene_gt_info.json", DatasetError,
                                      where, item="gt")
            self._checked[key] = (cam, gts, infos)
        return self._checked[key]

    # -- models -----------------------------------------------------------------------------
    @property
    def object_ids(self) -> dict[int, str]:
        """Map obj_id -> object name (``obj_NNNNNN`` unless ``models_info.json`` has ``obj_name``)."""
        return {oid: str(v.get("obj_name", f"obj_{oid:06d}")) for oid, v in sorted(self.models_info.items())}

    def is_symmetric(self, obj_id: int) -> bool:
        """Whether ADD-S applies to ``obj_id`` (symmetry annotations, or the ``symmetric_ids`` override)."""
        if self.symmetric_ids is not None:
            return int(obj_id) in self.symmetric_ids
        return _is_symmetric(self.models_info.get(int(obj_id), {}))

    def _model_path(self, obj_id: int) -> Path:
        return self.models_path / f"obj_{obj_id:06d}.ply"

    def model(self, obj_id: int) -> ObjectModel:
        """Reference model of ``obj_id`` (vertices in metres, normals, colours), cached.

        Read by :func:`sixdpose.datasets.ply.read_ply`: colours come from the vertex colours or, for
        textured BOP models, from the texture sampled at each vertex's uv (a missing texture is one
        warning and a model without colours). Normals are the PLY's vertex normals, else computed
        from the mesh faces.
        """
        obj_id = int(obj_id)
        if obj_id in self._models:
            return self._models[obj_id]
        if obj_id not in self.models_info:
            raise DatasetError(f"{self.models_path / 'models_info.json'}: no object with obj_id {obj_id}")
        ply = read_ply(self._model_path(obj_id))
        pts = ply.vertices / 1000.0
        tris = ply.faces if ply.faces is not None else np.zeros((0, 3), np.int64)
        nrm = ply.normals
        if nrm is None and len(tris):
            nrm = vertex_normals(pts, tris)
        if nrm is not None:
            nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
        info = self.models_info[obj_id]
        m = ObjectModel(
            self.object_ids[obj_id], obj_id, pts, nrm, ply.colors, float(info["diameter"]) / 1000.0,
            self.is_symmetric(obj_id),
            mesh=(pts, tris) if len(tris) else None,
            symmetries={k: info[k] for k in ("symmetries_discrete", "symmetries_continuous", "diameter") if k in info}
            if _is_symmetric(info) else None,
        )
        self._models[obj_id] = m
        return m


# ------------------------------------------------------------------------------------------
# export of any reader (synthetic layout) to BOP
# ------------------------------------------------------------------------------------------
def _symmetry_axis(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Estimate the axis of a continuous symmetry: the principal axis whose variance differs most
    from the other two (plate: its normal; sphere: arbitrary). Returns (axis (3,), centre (3,))."""
    c = points.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((points - c).T))
    d = [abs(w[i] - np.mean(np.delete(w, i))) for i in range(3)]
    return v[:, int(np.argmax(d))], c


def export_bop(dataset, out: str | Path, split: str = "test", depth_scale: float = 0.1, progress: bool = True) -> Path:
    """Write ``dataset`` (any reader of the :mod:`.base` interface) as a BOP dataset.

    Args:
        dataset: e.g. a :class:`~sixdpose.datasets.synthetic.SyntheticDataset`.
        out: BOP root to create: a new or empty directory, or an unfinished export of ours (rewritten);
            a finished export or any other non-empty directory is refused before anything is written.
        split: split folder name to write.
        depth_scale: BOP depth unit in mm (0.1 -> 16-bit range up to 6.55 m, resolution 0.1 mm);
            depths beyond the 16-bit range are written as 0 (no measurement) with a warning.
        progress: show a tqdm bar.
    Returns:
        The output root. Models are written in mm with normals/colours; symmetric objects get a
        ``symmetries_continuous`` entry whose axis is estimated from the model's principal axes
        (the bop_toolkit uses it only for MSSD/MSPD; ADD-S needs just the flag).
    Raises:
        DatasetError: ``out`` holds a finished export; ``split`` is not a plain folder name (a path
            separator, ``..``, absolute); ``depth_scale`` is not a positive finite number. Nothing is
            written then. OutputError: ``out`` is a non-empty directory that is not an export of ours.
    """
    from tqdm import tqdm

    from ..fileio import atomic_write_bytes, atomic_write_json, atomic_write_text, claim_output_dir
    from .layout import png_bytes
    from .ply import write_ply

    schemas.safe_name(split, "--split", DatasetError)
    try:
        depth_scale = float(depth_scale)
    except (TypeError, ValueError):
        raise DatasetError(f"--depth-scale: expected a positive number of mm per depth unit, got {depth_scale!r}") \
            from None
    if not (np.isfinite(depth_scale) and depth_scale > 0):
        raise DatasetError(f"--depth-scale: expected a positive number of mm per depth unit (0.1 for 0.1 mm), "
                           f"got {depth_scale:g}")
    out = Path(out)
    if (out / "models" / "models_info.json").exists() and (out / "dataset_info.md").exists():
        raise DatasetError(f"{out}: already holds a finished export; choose a new --out")
    claim_output_dir(out, "export-bop")  # an interrupted export of ours is rewritten; anything else refused
    (out / "models").mkdir(parents=True, exist_ok=True)
    info = {}
    for oid, name in sorted(dataset.object_ids.items()):
        m = dataset.model(oid)
        mm = m.points * 1000.0
        write_ply(out / "models" / f"obj_{oid:06d}.ply", mm, m.normals, m.colors)
        lo, hi = mm.min(axis=0), mm.max(axis=0)
        e = {
            "diameter": m.diameter * 1000.0,
            "min_x": lo[0], "min_y": lo[1], "min_z": lo[2],
            "size_x": hi[0] - lo[0], "size_y": hi[1] - lo[1], "size_z": hi[2] - lo[2],
            "obj_name": name,
        }
        if m.symmetric:
            axis, c = _symmetry_axis(mm)
            e["symmetries_continuous"] = [{"axis": axis.tolist(), "offset": c.tolist()}]
        info[str(oid)] = {k: (float(v) if isinstance(v, (np.floating, float)) else v) for k, v in e.items()}
    atomic_write_json(out / "models" / "models_info.json", info)

    scenes: dict[int, dict[str, dict]] = {}
    cam_written = False
    keys = dataset.keys()
    n_clipped = 0
    for index, (_sid, _im) in enumerate(tqdm(keys, desc="export-bop", disable=not progress, unit="img")):
        s: Sample = dataset[index]
        sd = out / split / f"{s.scene_id:06d}"
        if s.scene_id not in scenes:
            for sub in ("rgb", "depth", "mask_visib"):
                (sd / sub).mkdir(parents=True, exist_ok=True)
            scenes[s.scene_id] = {"gt": {}, "cam": {}, "info": {}}
        h, w = s.rgb.shape[:2]
        atomic_write_bytes(sd / "rgb" / f"{s.im_id:06d}.png", png_bytes(s.rgb))
        if s.depth is not None:
            raw = np.round(np.nan_to_num(s.depth, nan=0.0) * (1000.0 / depth_scale))
            over = raw > 65535
            n_clipped += int(over.sum())
            raw[over | (raw < 0)] = 0
            atomic_write_bytes(sd / "depth" / f"{s.im_id:06d}.png", png_bytes(raw.astype(np.uint16)))
        gts, infos = [], []
        for k, inst in enumerate(s.instances):
            gts.append({
                "cam_R_m2c": inst.R.reshape(-1).tolist(),
                "cam_t_m2c": (inst.t * 1000.0).tolist(),
                "obj_id": int(inst.obj_id),
                "inst": int(inst.inst),
            })
            gi = {"px_count_visib": int(inst.px_visib)}
            if inst.mask is not None:
                atomic_write_bytes(sd / "mask_visib" / f"{s.im_id:06d}_{k:06d}.png",
                                   png_bytes(inst.mask.astype(np.uint8) * 255))
                ys, xs = np.nonzero(inst.mask)
                bb = ([int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]
                      if len(xs) else [-1, -1, -1, -1])
                gi["bbox_visib"] = bb
                if inst.px_visib < 0:
                    gi["px_count_visib"] = int(inst.mask.sum())
            infos.append(gi)
        scenes[s.scene_id]["gt"][str(s.im_id)] = gts
        scenes[s.scene_id]["cam"][str(s.im_id)] = {"cam_K": s.K.reshape(-1).tolist(), "depth_scale": depth_scale}
        scenes[s.scene_id]["info"][str(s.im_id)] = infos
        if not cam_written:
            K = s.K
            cam = {"cx": K[0, 2], "cy": K[1, 2], "fx": K[0, 0], "fy": K[1, 1], "width": w, "height": h,
                   "depth_scale": depth_scale}
            atomic_write_json(out / "camera.json",
                              {k: float(v) if k not in ("width", "height") else int(v) for k, v in cam.items()},
                              indent=2)
            cam_written = True
    for sid, d in scenes.items():
        sd = out / split / f"{sid:06d}"
        atomic_write_json(sd / "scene_gt.json", d["gt"])
        atomic_write_json(sd / "scene_camera.json", d["cam"])
        atomic_write_json(sd / "scene_gt_info.json", d["info"])
    if n_clipped:
        log.warning("%d depth pixels beyond the 16-bit range (%.2f m) were written as 0",
                    n_clipped, 65.535 * depth_scale)
    atomic_write_text(
        out / "dataset_info.md",
        f"# sixdpose synthetic dataset exported to BOP\n\nSource: {dataset.location}\n"
        f"Split: {split}; depth_scale {depth_scale} mm; models in mm; {len(keys)} images.\n"
        "Extra keys (ignored by bop_toolkit): models_info obj_name, scene_gt inst.\n"
    )
    return out
