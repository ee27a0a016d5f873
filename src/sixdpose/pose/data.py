"""Instance inputs of the learned stage: masked pixels with valid depth, sampled points, crops.

One instance = one mask in one image (ground-truth or predicted); several instances of the same
object in an image are separate samples. Every function works on a :class:`~sixdpose.datasets.base.Sample`
and plain arrays; randomness comes from an explicit ``numpy.random.Generator`` (deterministic per
epoch and item, so a resumed run is exact).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from ..datasets.geometry import backproject, mask_box
from ..errors import SixdposeError

#: ImageNet statistics used to normalise [0, 1] colours before the CNN.
MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)


class PoseError(SixdposeError):
    """Bad input to the learned pose stage (no usable instances, unknown classes, ...)."""


@dataclass
class InstanceInput:
    """The network input of one instance.

    Attributes:
        obj_id: object id. index: position of the instance in ``Sample.instances`` or the detection
            list. score: detection score (1.0 for ground-truth masks).
        image: (S, S, 3) uint8 crop (crop mode) or None (full-image mode: the frame's image is used).
        choose: (P,) int64 flat pixel indices into the crop / full image of the sampled points.
        cloud: (P, 3) float32 sampled camera-frame points, metres (wrapped repeats when fewer than P).
        points, colors: (n, 3) float64 every masked valid point (metres) and its colour in [0, 1]
            (for ICP / colour verification; only kept when asked).
        R, t: ground-truth pose ``X_CO`` (metres) when known, else None.
    """

    obj_id: int
    index: int
    score: float
    image: np.ndarray | None
    choose: np.ndarray
    cloud: np.ndarray
    points: np.ndarray | None = None
    colors: np.ndarray | None = None
    R: np.ndarray | None = None
    t: np.ndarray | None = None
    n_valid: int = 0


@dataclass
class Frame:
    """The instances of one image: ``image`` (H, W, 3) uint8 in full-image mode (None in crop mode)."""

    image: np.ndarray | None
    instances: list[InstanceInput] = field(default_factory=list)


def crop_window(mask: np.ndarray, margin: float, jitter: float = 0.0,
                rng: np.random.Generator | None = None) -> tuple[float, float, float]:
    """Square window around a mask's box: ``(y0, x0, side)`` in pixels (side >= 8), enlarged by ``margin`` per side.

    ``jitter`` > 0 (training only, needs ``rng``): the side is scaled by ``exp(U(-jitter, jitter))`` and
    the centre moved by ``U(-jitter, jitter) * side / 2`` along each axis, as a detector's box would vary.
    """
    box = mask_box(np.asarray(mask, dtype=bool))
    if box is None:
        raise ValueError("crop_window: the mask is empty")
    v0, v1, u0, u1 = box
    side = max(float(max(v1 - v0, u1 - u0)) * (1.0 + 2.0 * margin), 8.0)
    cy, cx = (v0 + v1) / 2.0, (u0 + u1) / 2.0
    if jitter > 0 and rng is not None:
        dy, dx, ds = rng.uniform(-jitter, jitter, size=3)
        cy, cx = cy + dy * side / 2.0, cx + dx * side / 2.0
        side = max(side * float(np.exp(ds)), 8.0)
    return cy - side / 2.0, cx - side / 2.0, side


def crop_image(rgb: np.ndarray, y0: float, x0: float, side: float, size: int) -> np.ndarray:
    """Nearest-neighbour crop of ``rgb`` (H, W, 3) over the square window, resized to (size, size, 3); black outside."""
    H, W = rgb.shape[:2]
    rows = np.floor(y0 + (np.arange(size) + 0.5) * side / size).astype(np.int64)
    cols = np.floor(x0 + (np.arange(size) + 0.5) * side / size).astype(np.int64)
    okr, okc = (rows >= 0) & (rows < H), (cols >= 0) & (cols < W)
    out = rgb[rows.clip(0, H - 1)[:, None], cols.clip(0, W - 1)[None, :], :3].copy()
    out[~okr] = 0
    out[:, ~okc] = 0
    return out


def extract_instance(rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, mask: np.ndarray, obj_id: int, *,
                     crop: int, margin: float, num_points: int, min_points: int, rng: np.random.Generator,
                     index: int = 0, score: float = 1.0, keep_points: bool = False,
                     depth_band: float = 0.0, crop_jitter: float = 0.0,
                     with_image: bool = True) -> InstanceInput | str:
    """Build the input of one instance, or return the reason it is unusable.

    Args:
        rgb: (H, W, 3) uint8. depth: (H, W) metres (0 / NaN / inf: invalid, ignored). K: (3, 3).
        mask: (H, W) bool. crop: 0 (full image) or the crop size in pixels. margin: crop enlargement.
        num_points: points sampled (without replacement when enough, else wrapped repeats).
        min_points: fewer valid depth pixels under the mask -> the reason string.
        rng: numpy generator. keep_points: keep every masked point and colour (ICP / colour check).
        depth_band: metres; > 0 drops the masked points whose depth is farther than this from the
            median depth under the mask (inference passes the object's diameter: no point of the object
            can lie farther, so with a ground-truth mask nothing is dropped, while the background seen
            through a predicted mask's loose edges is, which would otherwise drag the cloud's centroid
            and so the translation tens of centimetres back; it assumes most masked pixels lie on the
            object, as the median is taken over all of them). 0 keeps every point.
        crop_jitter: training augmentation of the crop window (:func:`crop_window`); 0 at inference.
        with_image: False for a network that reads no image (:attr:`~.model.PoseNet.reads_images`): no crop is
            cut (the instance's ``image`` is None, ``choose`` indexes the full image); the points are the same.
    Returns:
        :class:`InstanceInput` or a reason string such as ``"3 valid depth pixels under the mask (< 10)"``.
    """
    mask = np.asarray(mask, dtype=bool)
    pts, col, pix = backproject(depth, K, mask, rgb if keep_points else None)
    if depth_band > 0 and len(pts) and float(np.ptp(pts[:, 2])) > depth_band:  # else every point is in the band
        keep = np.abs(pts[:, 2] - np.median(pts[:, 2])) <= depth_band
        pts, pix = pts[keep], pix[keep]
        col = col[keep] if col is not None else None
    n = len(pts)
    if n < min_points:
        return f"{n} valid depth pixel(s) under the mask (< {min_points})"
    sel = rng.permutation(n)[:num_points] if n > num_points else np.resize(rng.permutation(n), num_points)
    v, u = pix[sel, 0], pix[sel, 1]
    if crop and with_image:
        y0, x0, side = crop_window(mask, margin, crop_jitter, rng)
        image = crop_image(rgb, y0, x0, side, crop)
        i = np.clip(np.floor((v + 0.5 - y0) * crop / side), 0, crop - 1).astype(np.int64)
        j = np.clip(np.floor((u + 0.5 - x0) * crop / side), 0, crop - 1).astype(np.int64)
        choose = i * crop + j
    else:
        image, choose = None, (v * depth.shape[1] + u).astype(np.int64)
    return InstanceInput(int(obj_id), int(index), float(score), image, choose, pts[sel].astype(np.float32),
                         pts if keep_points else None, col if keep_points else None, n_valid=n)


def normalise_images(images: np.ndarray, noise: float = 0.0, rng: np.random.Generator | None = None,
                     jitter: float = 0.0) -> torch.Tensor:
    """(B, H, W, 3) uint8 -> (B, 3, H, W) float32 normalised (ImageNet mean/std), optional augmentation.

    ``jitter`` > 0 (training only): every image gets its own colour transform of the [0, 1] colours,
    ``x -> clip(g_c * x ** gamma)`` with per-channel gains ``g_c = s * U(1 - jitter/2, 1 + jitter/2)``,
    a brightness ``s ~ U(1 - jitter, 1 + jitter)`` and ``gamma = exp(U(-jitter, jitter))``: another
    camera's white balance, exposure and response curve (domain randomisation for real frames).
    ``noise`` > 0 then adds U(-noise, noise) per pixel and channel (clipped).
    """
    x = images.astype(np.float32) / 255.0
    if jitter > 0:
        B = len(x)
        gamma = np.exp(rng.uniform(-jitter, jitter, size=(B, 1, 1, 1))).astype(np.float32)
        gain = (rng.uniform(1 - jitter, 1 + jitter, size=(B, 1, 1, 1))
                * rng.uniform(1 - jitter / 2, 1 + jitter / 2, size=(B, 1, 1, 3))).astype(np.float32)
        x = np.clip(gain * x ** gamma, 0.0, 1.0)
    if noise > 0:
        x = np.clip(x + rng.uniform(-noise, noise, size=x.shape).astype(np.float32), 0.0, 1.0)
    x = (x - MEAN) / STD
    return torch.from_numpy(np.ascontiguousarray(x.transpose(0, 3, 1, 2)))


def collate_frames(frames: list[Frame], class_index: dict[int, int], noise: float = 0.0,
                   rng: np.random.Generator | None = None, jitter: float = 0.0) -> dict:
    """Batch the instances of several frames for one forward pass.

    Crop mode: one image per instance. Full-image mode: one image per frame (its instances share the
    CNN pass). Neither (instances without crops and frames without images, for a network that reads no
    image): ``images`` is an empty (0, 3, 1, 1) tensor. ``noise``, ``jitter``: training augmentation
    (:func:`normalise_images`). Returns a dict
    of CPU tensors: ``images`` (B, 3, H, W), ``img_index`` (N,), ``choose`` (N, P), ``cloud`` (N, P, 3),
    ``obj_index`` (N,), and ``R`` (N, 3, 3) / ``t`` (N, 3) float32 when every instance has ground truth;
    ``instances``: the :class:`InstanceInput` list.
    """
    insts = [i for f in frames for i in f.instances]
    if not insts:
        return {"instances": []}
    keep = [f for f in frames if f.instances]
    if insts[0].image is not None:
        imgs = np.stack([i.image for i in insts])
        img_index = np.arange(len(insts))
    elif all(f.image is None for f in keep):  # a network that reads no image: nothing to normalise
        imgs, img_index = None, np.zeros(len(insts), np.int64)
    else:
        imgs = np.stack([f.image[..., :3] for f in keep])
        img_index = np.concatenate([np.full(len(f.instances), k) for k, f in enumerate(keep)])
    out = {
        "images": normalise_images(imgs, noise, rng, jitter) if imgs is not None else torch.zeros(0, 3, 1, 1),
        "img_index": torch.from_numpy(img_index.astype(np.int64)),
        "choose": torch.from_numpy(np.stack([i.choose for i in insts])),
        "cloud": torch.from_numpy(np.stack([i.cloud for i in insts])),
        "obj_index": torch.tensor([class_index[i.obj_id] for i in insts], dtype=torch.long),
        "instances": insts,
    }
    if all(i.R is not None for i in insts):
        out["R"] = torch.from_numpy(np.stack([i.R for i in insts]).astype(np.float32))
        out["t"] = torch.from_numpy(np.stack([i.t for i in insts]).astype(np.float32))
    return out


def sample_model_points(model_points: dict[int, np.ndarray], obj_ids, m: int, rng: np.random.Generator) -> torch.Tensor:
    """A fresh random subset of ``m`` model points per instance: (N, m, 3) float32 (object frame, metres)."""
    out = []
    for oid in obj_ids:
        P = model_points[oid]
        sel = rng.choice(len(P), m, replace=len(P) < m)
        out.append(P[sel])
    return torch.from_numpy(np.stack(out).astype(np.float32))


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two boolean masks."""
    inter = np.logical_and(a, b).sum()
    union = np.logical_or(a, b).sum()
    return float(inter / union) if union else 0.0


def training_masks(sample, detections=None, iou_min: float = 0.5) -> list[tuple[int, np.ndarray, int]]:
    """Masks to train on, as ``(index into sample.instances, mask, obj_id)``.

    ``detections`` None: the ground-truth masks. Otherwise each predicted mask is matched (greedy, by
    decreasing score) to the unmatched ground-truth instance of the same object with the highest IoU
    >= ``iou_min``; it keeps that instance's pose as the target.
    """
    if detections is None:
        return [(k, g.mask, g.obj_id) for k, g in enumerate(sample.instances) if g.mask is not None]
    used, out = set(), []
    for d in detections:
        best, bk = iou_min, None
        for k, g in enumerate(sample.instances):
            if k in used or g.obj_id != d.obj_id or g.mask is None:
                continue
            iou = mask_iou(d.mask, g.mask)
            if iou >= best:
                best, bk = iou, k
        if bk is not None:
            used.add(bk)
            out.append((bk, d.mask, d.obj_id))
    return out


@dataclass(frozen=True)
class Augment:
    """Training-time augmentation of an instance's mask and depth, as real frames and predicted masks differ
    from rendered ones (all off by default; :class:`~sixdpose.pose.config.PoseConfig` fields of the same
    meaning: ``mask_jitter_px``, ``depth_noise``, ``depth_holes``, ``crop_jitter``, ``occlusion``).

    Attributes:
        mask_px: the mask is eroded or dilated by ``k ~ U{-mask_px..mask_px}`` pixels (a predicted mask's
            loose or tight edge: dilation brings background points in, which the dense head learns to give
            a low confidence). An erosion that would leave nothing keeps the mask.
        depth_noise: metres; standard deviation of the Gaussian axial noise added to the masked depth,
            scaled per instance by ``U(0, 1)`` (a sensor noisier than the simulated one).
        holes: largest fraction of the masked depth pixels removed as a few random discs (``U(0, holes)``
            of the mask's area; a real sensor's missing returns on dark or shiny parts).
        crop: crop-window jitter (:func:`crop_window`).
        occlusion: largest fraction of the mask hidden behind a straight occluder edge: for half the instances
            the pixels beyond a line across the mask (a uniformly random direction in the image) are removed,
            ``U(0, occlusion)`` of the mask's area (an object in front hiding one side of this one, as real
            scenes' objects standing behind others are; rendered clutter hides less).
    """

    mask_px: int = 0
    depth_noise: float = 0.0
    holes: float = 0.0
    crop: float = 0.0
    occlusion: float = 0.0

    @classmethod
    def of(cls, cfg) -> Augment:
        """The augmentation of a config (a :class:`~sixdpose.pose.config.PoseConfig`; other configs: none)."""
        return cls(int(getattr(cfg, "mask_jitter_px", 0)), float(getattr(cfg, "depth_noise", 0.0)),
                   float(getattr(cfg, "depth_holes", 0.0)), float(getattr(cfg, "crop_jitter", 0.0)),
                   float(getattr(cfg, "occlusion", 0.0)))

    @property
    def touches_depth(self) -> bool:
        """Whether :meth:`apply` changes depth (the caller then passes a copy it may write)."""
        return self.depth_noise > 0 or self.holes > 0

    def apply(self, mask: np.ndarray, depth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The augmented mask (H, W) bool; ``depth`` (H, W, metres) is changed in place under it (noise, holes).

        Works on the mask's bounding box (padded by ``mask_px``), so it costs little on a 640x480 frame.
        """
        from scipy import ndimage

        mask = np.asarray(mask, dtype=bool)
        box = mask_box(mask)
        if box is None:
            return mask
        H, W = mask.shape
        p = self.mask_px + 1
        r0, r1, c0, c1 = max(box[0] - p, 0), min(box[1] + p, H), max(box[2] - p, 0), min(box[3] + p, W)
        sub = mask[r0:r1, c0:c1]
        k = int(rng.integers(-self.mask_px, self.mask_px + 1)) if self.mask_px else 0
        if k > 0:
            sub = ndimage.binary_dilation(sub, iterations=k)
        elif k < 0:
            eroded = ndimage.binary_erosion(sub, iterations=-k)
            sub = eroded if eroded.any() else sub
        if self.occlusion > 0 and rng.random() < 0.5:
            sv, su = np.nonzero(sub)
            a = rng.uniform(0.0, 2 * np.pi)
            proj = sv * np.sin(a) + su * np.cos(a)
            frac = rng.uniform(0.0, self.occlusion)
            if frac > 0 and len(proj):
                cut = proj > np.quantile(proj, 1.0 - frac)
                sub = sub.copy()
                sub[sv[cut], su[cut]] = False
        out = np.zeros_like(mask)
        out[r0:r1, c0:c1] = sub
        if not self.touches_depth:
            return out
        d = depth[r0:r1, c0:c1]  # a view: written in place
        if self.holes > 0:
            area = float(sub.sum())
            n = int(rng.integers(1, 5))
            radius = np.sqrt(rng.uniform(0.0, self.holes) * area / (n * np.pi))
            sv, su = np.nonzero(sub)
            pick = rng.integers(0, len(sv), size=n)
            yy, xx = np.mgrid[0:sub.shape[0], 0:sub.shape[1]]
            for cy, cx in zip(sv[pick], su[pick], strict=True):
                d[sub & ((yy - cy) ** 2 + (xx - cx) ** 2 <= radius ** 2)] = 0.0
        if self.depth_noise > 0:
            sigma = self.depth_noise * rng.uniform(0.0, 1.0)
            on = sub & (d > 0)
            d[on] = np.maximum(d[on] + rng.normal(0.0, sigma, size=int(on.sum())), 0.0)
        return out


class FrameDataset(torch.utils.data.Dataset):
    """Training frames: item ``i`` = the usable instances of image ``keys[i]`` with their targets.

    Args:
        reader: a DatasetReader. keys: image keys (repeats allowed). cfg: a PoseConfig or RefinerConfig
            (``num_points``, ``min_points``; ``crop``/``crop_margin`` come from ``crop``, ``margin``).
        class_index: obj_id -> class index (others are skipped). crop, margin: crop settings of the
            main network. masks: ``"gt"`` or a prediction directory. seed: base seed.
    """

    def __init__(self, reader, keys, cfg, class_index, crop: int, margin: float, masks: str = "gt", seed: int = 0):
        self.reader, self.keys, self.cfg, self.class_index = reader, list(keys), cfg, class_index
        self.crop, self.margin, self.masks, self.seed = crop, margin, masks, seed
        self.augment = Augment.of(cfg)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the epoch (seeds the per-item sampling)."""
        self.epoch = epoch

    def _band(self, obj_id: int) -> float:
        """The object's diameter (metres): the depth band of a dilated mask, as inference uses it."""
        bands = self.__dict__.setdefault("_bands", {})
        if obj_id not in bands:
            bands[obj_id] = float(self.reader.model(obj_id).diameter)
        return bands[obj_id]

    def __len__(self):
        return len(self.keys)

    def __getitem__(self, i: int) -> Frame:
        rng = np.random.default_rng([self.seed, self.epoch, i])
        key = self.keys[i]
        s = self.reader.load(key)
        dets = None
        if self.masks != "gt":
            from ..artifacts.predictions import read_predictions

            dets = read_predictions(self.masks, *key)
        frame = Frame(None if self.crop else s.rgb)
        aug = self.augment
        depth = s.depth
        for k, mask, oid in training_masks(s, dets):
            if oid not in self.class_index:
                continue
            if aug != Augment():
                depth = s.depth.copy() if aug.touches_depth else s.depth  # each instance from the frame's own depth
                mask = aug.apply(mask, depth, rng)
            inst = extract_instance(s.rgb, depth, s.K, mask, oid, crop=self.crop, margin=self.margin,
                                    num_points=self.cfg.num_points, min_points=self.cfg.min_points, rng=rng, index=k,
                                    crop_jitter=aug.crop, depth_band=self._band(oid) if aug.mask_px else 0.0)
            if isinstance(inst, str):
                continue
            inst.R, inst.t = s.instances[k].R, s.instances[k].t
            frame.instances.append(inst)
        return frame


def collate_list(batch):
    """``collate_fn`` keeping frames as a list."""
    return list(batch)
