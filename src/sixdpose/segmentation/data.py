"""Datasets -> Mask R-CNN training data: class map, train/test split, scan, augmentation.

Everything here goes through the reader interface of :mod:`sixdpose.datasets` (``len``,
``__getitem__ -> Sample``, ``keys()``, ``object_ids``); no file of a dataset layout is read directly.

Split policy (section IV-A):
    * synthetic layout: a seeded random split of the images (``val_fraction`` held out, 10% in the
      paper profile); ``split_by="scene"`` keeps all views of a scene on one side instead.
    * BOP layout: the split directories as given (``train_split`` / ``test_split``; for LM-O the
      PoseCNN protocol corresponds to BOP's ``train`` (or ``train_pbr``) and ``test``).
The split is written to ``RUN_DIR/split.json`` and reused on resume, by ``segment --subset`` and by
the evaluation.

Bad input is never silently used: before training, the training images are scanned once; images with
no usable annotation are skipped, instances with an empty (or too small) mask or an object that is
not a class are dropped, classes without any training instance are reported -- each logged with the
image keys, and recorded in ``split.json``. A split without instance masks is an error.

Augmentation (training only; documented choice, the paper does not specify one): photometric colour
jitter (brightness, contrast, saturation, hue; random order is not used), an optional horizontal flip
(off by default), and multi-scale training done by the model's resize (see :mod:`.model`). Random
draws come from a generator seeded by ``(seed, epoch, image index)``, so augmentation is identical
whatever the number of workers or processes, and across ``--resume``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..datasets.base import DatasetError, Sample
from ..datasets.geometry import mask_box
from ..datasets.readers import open_dataset
from .config import SegConfig

log = logging.getLogger("sixdpose.segmentation")

Key = tuple[int, int]


# ---------------------------------------------------------------------------------------------
# classes
@dataclass
class ClassMap:
    """Mapping between dataset object ids and contiguous Mask R-CNN labels (1..C; 0 = background).

    Attributes:
        obj_ids: object id of label ``i + 1`` at position ``i`` (ascending).
        names: object name of each entry of ``obj_ids``.
    """

    obj_ids: list[int]
    names: list[str]

    @classmethod
    def from_dataset(cls, ds) -> ClassMap:
        """All objects of ``ds.object_ids`` (the dataset's target objects), sorted by id."""
        ids = ds.object_ids
        if not ids:
            raise DatasetError(f"{ds.location}: the dataset declares no objects")
        keys = sorted(int(k) for k in ids)
        return cls(keys, [str(ids[k]) for k in keys])

    @classmethod
    def from_list(cls, pairs) -> ClassMap:
        """From ``[[obj_id, name], ...]`` as written by :meth:`to_list`."""
        return cls([int(p[0]) for p in pairs], [str(p[1]) for p in pairs])

    def to_list(self) -> list[list]:
        """``[[obj_id, name], ...]`` (JSON-compatible)."""
        return [[i, n] for i, n in zip(self.obj_ids, self.names, strict=True)]

    def __len__(self) -> int:
        return len(self.obj_ids)

    def label_of(self, obj_id: int) -> int | None:
        """The Mask R-CNN label of ``obj_id``, or ``None`` if it is not a class."""
        try:
            return self.obj_ids.index(int(obj_id)) + 1
        except ValueError:
            return None

    def obj_id_array(self) -> np.ndarray:
        """Lookup table label -> obj_id (index 0, background, maps to 0)."""
        return np.array([0] + self.obj_ids, dtype=np.int64)

    def check_compatible(self, ds) -> None:
        """Raise :class:`DatasetError` if an object id of ``ds`` names a different object than here.

        Objects of the dataset that are not classes are allowed (they are never predicted); an id
        shared with a different name means the checkpoint was trained on another dataset.
        """
        theirs = {int(k): str(v) for k, v in ds.object_ids.items()}
        clashes = [
            (i, n, theirs[i]) for i, n in zip(self.obj_ids, self.names, strict=True) if i in theirs and theirs[i] != n
        ]
        if clashes:
            i, a, b = clashes[0]
            raise DatasetError(
                f"incompatible checkpoint: it was trained with obj_id {i} = {a!r}, but the dataset's obj_id {i} "
                f"is {b!r} ({len(clashes)} such id(s)); it was trained on a different dataset"
            )
        if not set(self.obj_ids) & set(theirs):
            raise DatasetError(
                f"incompatible checkpoint: none of its objects {self.obj_ids} is an object of the dataset "
                f"({sorted(theirs)})"
            )


# ---------------------------------------------------------------------------------------------
# split
def is_synthetic(ds) -> bool:
    """Whether ``ds`` is the paper's synthetic layout (random split) rather than BOP (split dirs)."""
    from ..datasets.synthetic import SyntheticDataset

    return isinstance(ds, SyntheticDataset)


def make_split(data: str | Path, cfg: SegConfig) -> dict:
    """Decide the train / test images of a run (see the module docstring for the policy).

    Returns:
        ``{"policy": str, "train": {"split": name, "keys": [[scene, im], ...]}, "test": {...}}``;
        ``split`` is the reader's split argument (``None`` for the synthetic layout).
    """
    ds = open_dataset(data, split=cfg.train_split)
    if is_synthetic(ds):
        keys = [tuple(map(int, k)) for k in ds.keys()]  # noqa: SIM118 (a dataset reader's keys(), not a dict)
        if not keys:
            raise DatasetError(f"{data}: the dataset has no images")
        rng = np.random.default_rng(cfg.seed)
        groups = sorted({k[0] for k in keys}) if cfg.split_by == "scene" else list(range(len(keys)))
        n_test = int(round(cfg.val_fraction * len(groups)))
        n_test = min(max(n_test, 1), len(groups) - 1) if cfg.val_fraction > 0 and len(groups) >= 2 else 0
        perm = rng.permutation(len(groups))
        test_groups = {groups[i] for i in perm[:n_test]}
        if cfg.split_by == "scene":
            is_test = [k[0] in test_groups for k in keys]
        else:
            is_test = [i in test_groups for i in range(len(keys))]
        train = [list(k) for k, t in zip(keys, is_test, strict=True) if not t]
        test = [list(k) for k, t in zip(keys, is_test, strict=True) if t]
        policy = f"random {cfg.split_by} split, val_fraction={cfg.val_fraction}, seed={cfg.seed}"
        return {"policy": policy, "train": {"split": None, "keys": train}, "test": {"split": None, "keys": test}}
    train = [list(map(int, k)) for k in ds.keys()]  # noqa: SIM118 (a dataset reader's keys(), not a dict)
    try:
        test_ds = open_dataset(data, split=cfg.test_split)
        test = [list(map(int, k)) for k in test_ds.keys()]  # noqa: SIM118 (a dataset reader's keys(), not a dict)
    except DatasetError as e:
        log.warning("no test split %r (%s); the run has no held-out images", cfg.test_split, e)
        test = []
    policy = f"BOP split directories: train={cfg.train_split!r}, test={cfg.test_split!r}"
    return {
        "policy": policy,
        "train": {"split": cfg.train_split, "keys": train},
        "test": {"split": cfg.test_split, "keys": test},
    }


def open_part(data: str | Path, split: dict, part: str):
    """Open the reader of ``split[part]`` and return ``(dataset, indices)`` of its images."""
    rec = split[part]
    ds = open_dataset(data, split=rec["split"] or "test")
    index = {tuple(map(int, k)): i for i, k in enumerate(ds.keys())}
    missing = [k for k in rec["keys"] if tuple(k) not in index]
    if missing:
        raise DatasetError(
            f"{data}: {len(missing)} image(s) of the run's {part} split are not in the dataset "
            f"(first: scene {missing[0][0]} image {missing[0][1]}); is this the dataset the run was trained on?"
        )
    return ds, [index[tuple(k)] for k in rec["keys"]]


# ---------------------------------------------------------------------------------------------
# scan
@dataclass
class ScanResult:
    """What the pre-training scan of the training images found.

    Attributes:
        usable: dataset indices with at least one usable instance.
        skipped_images: ``[[scene, im, reason], ...]`` of images left out.
        dropped_instances: ``[[scene, im, obj_id, inst, reason], ...]`` of instances left out.
        class_counts: obj_id -> number of usable training instances.
        missing_classes: class obj_ids without a single training instance.
    """

    usable: list[int] = field(default_factory=list)
    skipped_images: list[list] = field(default_factory=list)
    dropped_instances: list[list] = field(default_factory=list)
    class_counts: dict[int, int] = field(default_factory=dict)
    missing_classes: list[int] = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-compatible dict (for ``split.json``)."""
        return {
            "usable": self.usable,
            "skipped_images": self.skipped_images,
            "dropped_instances": self.dropped_instances,
            "class_counts": {str(k): v for k, v in self.class_counts.items()},
            "missing_classes": self.missing_classes,
        }

    @classmethod
    def from_dict(cls, d: dict) -> ScanResult:
        """Inverse of :meth:`to_dict`."""
        return cls(
            list(d["usable"]),
            list(d["skipped_images"]),
            list(d["dropped_instances"]),
            {int(k): int(v) for k, v in d["class_counts"].items()},
            list(d["missing_classes"]),
        )


def usable_instances(sample: Sample, classes: ClassMap, min_pixels: int):
    """Split the instances of ``sample`` into usable ones and dropped ``(instance, reason)`` pairs.

    Raises:
        DatasetError: an instance has no mask (the split carries no visible masks).
    """
    keep, drop = [], []
    for inst in sample.instances:
        if inst.mask is None:
            raise DatasetError(
                f"scene {sample.scene_id} image {sample.im_id}: instance of obj_id {inst.obj_id} has no mask; "
                "Mask R-CNN training and evaluation need visible instance masks (BOP: mask_visib)"
            )
        if inst.mask.shape != sample.rgb.shape[:2]:
            raise DatasetError(
                f"scene {sample.scene_id} image {sample.im_id}: mask of obj_id {inst.obj_id} has shape "
                f"{inst.mask.shape}, the image {sample.rgb.shape[:2]}"
            )
        if classes.label_of(inst.obj_id) is None:
            drop.append((inst, f"obj_id {inst.obj_id} is not a class"))
            continue
        npix = int(np.count_nonzero(inst.mask))
        if npix < max(min_pixels, 1):
            drop.append((inst, "empty mask" if npix == 0 else f"mask of {npix} px < min_mask_pixels"))
            continue
        keep.append(inst)
    return keep, drop


class _ScanView(torch.utils.data.Dataset):
    def __init__(self, ds, indices, classes, min_pixels):
        self.ds, self.indices, self.classes, self.min_pixels = ds, indices, classes, min_pixels

    def __len__(self):
        return len(self.indices)

    def __getitem__(self, i):
        s = self.ds[self.indices[i]]
        keep, drop = usable_instances(s, self.classes, self.min_pixels)
        return (
            self.indices[i],
            (s.scene_id, s.im_id),
            [k.obj_id for k in keep],
            [(d.obj_id, d.inst, r) for d, r in drop],
        )


def scan(ds, indices: list[int], classes: ClassMap, cfg: SegConfig, num_workers: int = 0) -> ScanResult:
    """Read every training image once and decide what is usable (see the module docstring).

    Raises:
        DatasetError: the split has no masks, or no image has a usable instance.
    """
    view = _ScanView(ds, indices, classes, cfg.min_mask_pixels)
    loader = torch.utils.data.DataLoader(view, batch_size=None, num_workers=num_workers)
    res = ScanResult(class_counts={i: 0 for i in classes.obj_ids})
    for idx, key, kept, dropped in loader:
        for obj_id, inst, reason in dropped:
            res.dropped_instances.append([key[0], key[1], int(obj_id), int(inst), reason])
        if kept:
            res.usable.append(int(idx))
            for o in kept:
                res.class_counts[int(o)] += 1
        else:
            why = "no annotated instance" if not dropped else "no usable instance (all dropped)"
            res.skipped_images.append([key[0], key[1], why])
    res.missing_classes = [i for i in classes.obj_ids if res.class_counts[i] == 0]
    for s, i, why in res.skipped_images:
        log.warning("skipping training image scene %d image %d: %s", s, i, why)
    for s, i, o, k, why in res.dropped_instances:
        log.info("dropping instance obj_id %d inst %d of scene %d image %d: %s", o, k, s, i, why)
    if res.dropped_instances:
        log.warning(
            "dropped %d training instance(s) (empty/small masks or non-class objects)", len(res.dropped_instances)
        )
    if res.missing_classes:
        names = dict(zip(classes.obj_ids, classes.names, strict=True))
        log.warning(
            "class(es) without any training instance in this split, they cannot be learned: %s",
            ", ".join(f"{i} ({names[i]})" for i in res.missing_classes),
        )
    if not res.usable:
        raise DatasetError("no training image has a usable annotated instance; nothing to train on")
    return res


# ---------------------------------------------------------------------------------------------
# training view
def sample_to_target(sample: Sample, classes: ClassMap, min_pixels: int) -> tuple[torch.Tensor, dict]:
    """Convert a :class:`Sample` into torchvision's ``(image, target)`` for Mask R-CNN.

    The image is float32 (3, H, W) in [0, 1]; the target has ``boxes`` (N, 4) float32 (x0, y0, x1, y1
    enclosing the mask pixels), ``labels`` (N,) int64 (contiguous labels, not obj ids) and ``masks``
    (N, H, W) uint8. Unusable instances are dropped (see :func:`usable_instances`).
    """
    keep, _ = usable_instances(sample, classes, min_pixels)
    img = torch.from_numpy(np.ascontiguousarray(sample.rgb[..., :3])).permute(2, 0, 1).float().div_(255.0)
    H, W = sample.rgb.shape[:2]
    if keep:
        masks = np.stack([k.mask for k in keep]).astype(np.uint8)
        boxes = np.zeros((len(keep), 4), np.float32)
        for j, m in enumerate(masks):
            box = mask_box(m)
            assert box is not None  # the kept instances have pixels (usable_instances)
            v0, v1, u0, u1 = box
            boxes[j] = (u0, v0, u1, v1)
    else:
        masks = np.zeros((0, H, W), np.uint8)
        boxes = np.zeros((0, 4), np.float32)
    labels = np.array([classes.label_of(k.obj_id) for k in keep], dtype=np.int64)
    return img, {"boxes": torch.from_numpy(boxes), "labels": torch.from_numpy(labels), "masks": torch.from_numpy(masks)}


def augment(img: torch.Tensor, target: dict, cfg: SegConfig, gen: torch.Generator) -> tuple[torch.Tensor, dict]:
    """Apply the training augmentation (colour jitter, optional flip) with generator ``gen``."""
    import torchvision.transforms.functional as TF

    b, c, s, h = cfg.color_jitter

    def factor(strength):
        return float(1.0 + (torch.rand((), generator=gen) * 2 - 1) * strength)

    if b > 0:
        img = TF.adjust_brightness(img, factor(b))
    if c > 0:
        img = TF.adjust_contrast(img, factor(c))
    if s > 0:
        img = TF.adjust_saturation(img, factor(s))
    if h > 0:
        img = TF.adjust_hue(img, float((torch.rand((), generator=gen) * 2 - 1) * h))
    img = img.clamp_(0.0, 1.0)
    if cfg.hflip_prob > 0 and float(torch.rand((), generator=gen)) < cfg.hflip_prob:
        W = img.shape[-1]
        img = img.flip(-1)
        target = dict(target)
        target["masks"] = target["masks"].flip(-1)
        bx = target["boxes"].clone()
        bx[:, 0], bx[:, 2] = W - target["boxes"][:, 2], W - target["boxes"][:, 0]
        target["boxes"] = bx
    return img, target


class TrainView(torch.utils.data.Dataset):
    """The usable training images of a dataset as ``(image, target)`` pairs, augmented.

    Args:
        ds: a reader (:func:`~sixdpose.datasets.open_dataset`).
        indices: dataset indices to use (the scan's ``usable``).
        classes: the class map.
        cfg: the run config (augmentation, ``min_mask_pixels``, ``seed``).
        train: apply augmentation.
    """

    def __init__(self, ds, indices: list[int], classes: ClassMap, cfg: SegConfig, train: bool = True):
        self.ds, self.indices, self.classes, self.cfg, self.train = ds, list(indices), classes, cfg, train
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the augmentation draws of ``epoch`` (call before iterating)."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, i: int):
        sample = self.ds[self.indices[i]]
        img, target = sample_to_target(sample, self.classes, self.cfg.min_mask_pixels)
        if self.train:
            gen = torch.Generator().manual_seed((self.cfg.seed * 1_000_003 + self.epoch) * 1_000_003 + self.indices[i])
            img, target = augment(img, target, self.cfg, gen)
        return img, target


def collate(batch):
    """Keep images and targets as lists (images may differ in size)."""
    return [b[0] for b in batch], [b[1] for b in batch]
