"""Inference: a trained run -> per-image instance masks (the format the registration stage reads).

Output of ``sixdpose segment --data DIR --seg RUN_DIR --out PRED_DIR``: the predicted-masks artifact
(:mod:`sixdpose.artifacts.predictions`, its one writer and reader): ``PRED_DIR/<scene_id>_<im_id>.npz``
per image, ``PRED_DIR/coco_results.json`` and ``PRED_DIR/meta.json`` (checkpoint, classes, images,
score threshold).
"""

from __future__ import annotations

import json
import logging
import time
import warnings
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import torch
from torchvision.models.detection.transform import GeneralizedRCNNTransform

from ..artifacts.predictions import write_predictions, write_predictions_meta
from ..config import check_overrides
from ..datasets.base import DatasetError
from ..datasets.readers import as_reader, dataset_fingerprint
from ..errors import ConfigError
from ..fileio import atomic_write_json, claim_output_dir
from ..runs import pick_device
from . import checkpoint as ck
from .config import SegConfig
from .data import ClassMap, open_part
from .model import build_model, set_train_sizes

log = logging.getLogger("sixdpose.segmentation")


def coco_image_id(scene_id: int, im_id: int) -> int:
    """COCO ``image_id`` of an image, shared by the ground truth and the results: ``scene*10^6 + im``."""
    return int(scene_id) * 1_000_000 + int(im_id)


def encode_rle(mask: np.ndarray) -> dict:
    """COCO RLE of a bool (H, W) mask, with ``counts`` as a str (JSON-serialisable)."""
    from pycocotools import mask as mask_util

    rle = mask_util.encode(np.asfortranarray(mask.astype(np.uint8)))
    rle["counts"] = rle["counts"].decode("ascii")
    return rle


#: Fields of a run's :class:`~.config.SegConfig` that ``segment --set`` may change: they act at inference
#: only (the test-time resize, the RPN's test proposals, the detections kept, mixed precision).
INFERENCE_FIELDS = ("score_thresh", "detections_per_img", "min_size", "max_size", "rpn_pre_nms_test",
                    "rpn_post_nms_test", "amp")


def check_inference_overrides(overrides: dict | None) -> dict:
    """``overrides`` (field -> value) checked before any work: only :data:`INFERENCE_FIELDS`, each of
    the field's type and bounds (against the default config). Raises :class:`ConfigError`."""
    return check_overrides(SegConfig, overrides, INFERENCE_FIELDS, "segment")


class Segmenter:
    """A trained Mask R-CNN ready for inference.

    Args:
        ckpt: a run directory (its ``model.pt``, else ``last.pt``) or a checkpoint file.
        device: ``cpu``/``cuda``/``auto`` (default: the GPU when present).
        score_thresh: override the run's minimum detection score.
        overrides: other :data:`INFERENCE_FIELDS` of the run's config to change (``--set``).
        optimise: compile the backbone and feature pyramid for CPU inference with :func:`optimise_backbone`
            (``None``, the default: on the CPU only). The detections are those of the eager network (checked
            on one input when compiled; it falls back to the eager network otherwise).
    Raises:
        CheckpointError: the checkpoint is missing, corrupt or does not fit its config.
    """

    def __init__(self, ckpt: str | Path, device: str | None = None, score_thresh: float | None = None,
                 overrides: dict | None = None, optimise: bool | None = None):
        overrides = check_inference_overrides(overrides)
        c = ck.load(ckpt)
        self.path = ck.resolve(ckpt)
        try:
            cfg = SegConfig.from_dict(c["config"])
        except (ValueError, TypeError, KeyError) as e:
            raise ck.CheckpointError(
                f"{self.path}: incompatible checkpoint ({str(e).strip().splitlines()[0][:300]})"
            ) from None
        cfg = cfg.replace(**overrides)  # ConfigError (one line naming the field) for a bad --set
        if score_thresh is not None:
            cfg = cfg.replace(score_thresh=float(score_thresh))
        try:
            classes = ClassMap.from_list(c["classes"])
            model, _ = build_model(cfg, len(classes), init=c.get("init", "random"))
            model.load_state_dict(c["model"])
        except (ValueError, TypeError, KeyError, RuntimeError, IndexError) as e:
            raise ck.CheckpointError(
                f"{self.path}: incompatible checkpoint ({str(e).strip().splitlines()[0][:300]})"
            ) from None
        self.cfg, self.classes, self.epoch, self.init = cfg, classes, int(c["epoch"]), c.get("init", "?")
        self.device = pick_device(device)
        self.model = model.to(self.device).eval()
        set_train_sizes(self.model, cfg, training=False)
        self.model.transform.__class__ = _ResizeFirst  # the same transform, normalising the smaller image
        self._lut = classes.obj_id_array()
        self.optimised = False
        if optimise or (optimise is None and self.device.type == "cpu"):
            self.optimised = optimise_backbone(self.model, cfg)

    @torch.inference_mode()
    def predict(self, rgbs: list[np.ndarray], mask_thresh: float = 0.5) -> list[dict[str, np.ndarray]]:
        """Segment a batch of (H, W, 3) uint8 images.

        Returns:
            Per image ``{"masks": (N,H,W) bool at the input resolution, "labels": (N,) int32 obj ids,
            "scores": (N,) float32, "boxes": (N,4) float32 x0,y0,x1,y1}``, sorted by decreasing score.
        """
        ims = [
            torch.from_numpy(np.ascontiguousarray(r[..., :3])).to(self.device).permute(2, 0, 1).float().div_(255.0)
            for r in rgbs
        ]
        use_amp = self.cfg.amp and self.device.type == "cuda"
        with torch.autocast("cuda", dtype=torch.float16) if use_amp else nullcontext():
            outs = self.model(ims)
        res = []
        for o, r in zip(outs, rgbs, strict=True):
            scores = o["scores"].float().cpu().numpy().astype(np.float32)
            order = np.argsort(-scores, kind="stable")
            masks = (
                (o["masks"][:, 0] > mask_thresh).cpu().numpy()[order]
                if len(order)
                else np.zeros((0,) + r.shape[:2], bool)
            )
            labels = self._lut[o["labels"].cpu().numpy()[order]].astype(np.int32)
            res.append({
                "masks": masks.astype(bool, copy=False),
                "labels": labels,
                "scores": scores[order],
                "boxes": o["boxes"].float().cpu().numpy()[order].astype(np.float32),
            })
        return res


class _ResizeFirst(GeneralizedRCNNTransform):
    """torchvision's detection transform normalising the smaller of the image before and after the resize:
    the bilinear resize is a weighted mean of neighbouring pixels (weights summing to 1), so it commutes with
    the per-channel affine normalisation (the same network input up to float rounding). At the ``cpu``
    profile's 320 pixels the normalisation then runs over a third of a 640x480 frame's pixels, after the
    resize; an image enlarged (the ``paper`` profile's 800) is normalised first, as torchvision does.
    Inference only (:class:`Segmenter`): training keeps torchvision's transform."""

    def normalize(self, image: torch.Tensor) -> torch.Tensor:  # noqa: D102
        return image  # done in resize, before or after it

    def resize(self, image, target=None):  # noqa: D102
        h, w = image.shape[-2:]
        scale = min(float(self.min_size[-1]) / min(h, w), float(self.max_size) / max(h, w))
        if self.training or self.fixed_size is not None or scale >= 1.0:
            return super().resize(GeneralizedRCNNTransform.normalize(self, image), target)
        image, target = super().resize(image, target)
        return GeneralizedRCNNTransform.normalize(self, image), target


class _TracedBackbone(torch.nn.Module):
    """A compiled backbone in place of torchvision's: the same call, and the ``out_channels`` it reads."""

    def __init__(self, traced, out_channels: int):
        super().__init__()
        self.traced, self.out_channels = traced, out_channels

    def forward(self, x: torch.Tensor):  # noqa: D102
        return self.traced(x)


def optimise_backbone(model, cfg: SegConfig, atol: float = 1e-3) -> bool:
    """Compile ``model.backbone`` (the ResNet or MobileNet body and its feature pyramid) for CPU inference.

    The body is traced with TorchScript, frozen (batch norms folded into the convolutions, weights made
    constants) and passed through ``torch.jit.optimize_for_inference`` (oneDNN convolutions). On the
    2-core CPU this halves the MobileNetV3 backbone's time (``benchmarks/pose.py``); the region proposals
    and the heads stay eager (compiling them gained nothing measurable). The compiled body accepts any
    image size and batch (convolutions, pooling and the pyramid's resize to its neighbour's shape are
    traced symbolically); it is checked against the eager one on a random image of the test size, and
    kept only when every pyramid level agrees within ``atol`` (then the detections are the same up to
    float rounding: the masks of the 20 ``data/test`` frames measured were identical to the pixel).

    Args:
        model: an eval-mode torchvision ``MaskRCNN`` on the CPU (changed in place).
        cfg: its :class:`~.config.SegConfig` (``min_size``/``max_size`` give the example input's size).
        atol: largest absolute difference allowed between the eager and compiled features.
    Returns:
        True when the backbone was replaced, False when compiling failed or disagreed (logged; the eager
        backbone is kept).
    """
    bb = model.backbone
    h = int(cfg.min_size)
    w = int(min(cfg.max_size, round(cfg.min_size * 4 / 3)) + 31) // 32 * 32
    x = torch.rand(1, 3, (h + 31) // 32 * 32, w, generator=torch.Generator().manual_seed(0))
    try:
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # TracerWarnings about shapes read as Python numbers
            traced = torch.jit.trace(bb.eval(), x, strict=False, check_trace=False)
            compiled = torch.jit.optimize_for_inference(torch.jit.freeze(traced.eval()))
            ref, got = bb(x), compiled(x)
            worst = max(float((ref[k] - got[k]).abs().max()) for k in ref)
    except (RuntimeError, TypeError, ValueError, KeyError) as e:  # an op TorchScript cannot trace
        log.warning("segmentation backbone not compiled (%s); it runs eagerly", str(e).strip().splitlines()[0][:200])
        return False
    if not worst <= atol:
        log.warning("segmentation backbone not compiled: its features differ by %.3g from the eager ones", worst)
        return False
    model.backbone = _TracedBackbone(compiled, bb.out_channels)
    return True


class _Images(torch.utils.data.Dataset):
    def __init__(self, ds, indices):
        self.ds, self.indices = ds, indices

    def __len__(self):
        return len(self.indices)

    def __getitem__(self, i):
        s = self.ds[self.indices[i]]
        return s.scene_id, s.im_id, s.rgb


def _transpose(batch):
    return list(zip(*batch, strict=True))


def segment(
    data,
    ckpt: str | Path,
    out: str | Path,
    *,
    split: str = "test",
    subset: str = "all",
    batch_size: int = 4,
    device: str | None = None,
    score_thresh: float | None = None,
    num_workers: int = 0,
    progress: bool = True,
    overrides: dict | None = None,
) -> dict:
    """Segment every image of a dataset (or of the run's train/test subset) and write ``out``.

    Args:
        data: a :class:`~sixdpose.datasets.base.DatasetReader` or a dataset directory.
        ckpt: run directory or checkpoint file.
        out: prediction directory (created; one written by ``segment`` before is overwritten; any
            other non-empty directory is refused).
        split: BOP split to read (ignored for the synthetic layout) when ``subset == "all"``.
        subset: ``all`` images of ``data``/``split``, or the run's ``train`` / ``test`` images
            (needs ``ckpt`` to be a run directory with ``split.json``).
        batch_size: images per forward pass.
        device: ``cpu``/``cuda``/``auto``.
        score_thresh: minimum score kept (default: the run's ``score_thresh``, 0.05).
        num_workers: image-loading worker processes.
        progress: show a progress bar.
        overrides: :data:`INFERENCE_FIELDS` of the run's config to change (``--set``).
    Returns:
        ``{"images": n, "detections": n, "seconds": s, "images_per_s": r, "pred_dir": str}``.
    Raises:
        CheckpointError, DatasetError (incl. a checkpoint trained on other objects than the dataset's).
    """
    overrides = check_inference_overrides(overrides)
    claim_output_dir(out, "segment", create=False)  # refuse a foreign directory before loading anything
    seg = Segmenter(ckpt, device=device, score_thresh=score_thresh, overrides=overrides)
    if subset == "all":
        ds = as_reader(data, split=split)
        indices = list(range(len(ds)))
        reader_split = split
    elif subset in ("train", "test"):
        split_file = Path(ckpt) / "split.json"
        if not split_file.is_file():
            raise DatasetError(f"{split_file}: --subset {subset} needs --seg to be a run directory with split.json")
        record = json.loads(split_file.read_text())
        ds, indices = open_part(data, record, subset)
        reader_split = record[subset]["split"]
    else:
        raise ConfigError(f"subset must be all, train or test, not {subset!r}")
    seg.classes.check_compatible(ds)
    missing = sorted(set(int(k) for k in ds.object_ids) - set(seg.classes.obj_ids))
    if missing:
        log.warning("objects of the dataset the checkpoint was not trained on (never predicted): %s", missing)
    out = Path(out)
    claim_output_dir(out, "segment")
    loader = torch.utils.data.DataLoader(
        _Images(ds, indices), batch_size=batch_size, num_workers=num_workers, collate_fn=_transpose
    )
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(indices), desc="segment", leave=False, dynamic_ncols=True)
    results, images, n_det = [], [], 0
    t_model = 0.0
    for scene_ids, im_ids, rgbs in loader:
        t0 = time.perf_counter()
        preds = seg.predict(list(rgbs))
        t_model += time.perf_counter() - t0
        for s, i, rgb, p in zip(scene_ids, im_ids, rgbs, preds, strict=True):
            write_predictions(out, s, i, p["masks"], p["labels"], p["scores"], p["boxes"])
            images.append([int(s), int(i), int(rgb.shape[0]), int(rgb.shape[1])])
            n_det += len(p["labels"])
            for m, lab, sc, bx in zip(p["masks"], p["labels"], p["scores"], p["boxes"], strict=True):
                results.append({
                    "image_id": coco_image_id(s, i),
                    "category_id": int(lab),
                    "segmentation": encode_rle(m),
                    "bbox": [float(bx[0]), float(bx[1]), float(bx[2] - bx[0]), float(bx[3] - bx[1])],
                    "score": float(sc),
                })
        if bar is not None:
            bar.update(len(rgbs))
    if bar is not None:
        bar.close()
    atomic_write_json(out / "coco_results.json", results)
    meta = {
        "checkpoint": str(seg.path.resolve()),
        "epoch": seg.epoch,
        "classes": seg.classes.to_list(),
        "score_thresh": seg.cfg.score_thresh,
        "data": str(Path(ds.location).resolve()),
        "split": reader_split,  # reader split (BOP split directory; ignored by the synthetic layout)
        "dataset_fingerprint": dataset_fingerprint(ds),  # consumers refuse masks of another dataset
        "subset": subset,
        "images": images,
        "format": "sixdpose.artifacts.predictions: npz per image, masks (N,H,W) bool, labels (N,) int32 obj_id, "
                  "scores (N,) float32, boxes (N,4) float32",
    }
    write_predictions_meta(out, meta)
    return {
        "images": len(images),
        "detections": n_det,
        "seconds": t_model,
        "images_per_s": len(images) / t_model if t_model > 0 else float("nan"),
        "pred_dir": str(out),
    }
