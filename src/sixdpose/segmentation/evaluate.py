"""COCO-style evaluation of predicted instance masks and boxes (pycocotools).

The ground truth of the evaluated images is converted to a COCO dataset in memory: one category per
class of the checkpoint (``id`` = dataset obj id), one annotation per annotated instance with a
non-empty visible mask (RLE), its box enclosing the mask. Instances with an empty mask cannot be
detected and are left out (counted, logged); instances of objects that are not classes are left out.

Reported: mask and box AP (IoU 0.50:0.95), AP50, AP75, over all classes and per class. A class with no
ground-truth instance in the evaluated images has an undefined AP: it is reported as NaN (``--`` in
LaTeX), said in one log line, and excluded from the mean (pycocotools' convention).

Written by :func:`write_tables` to the output directory: ``seg_ap<tag>.csv`` and ``seg_ap<tag>.tex``,
each atomically (:mod:`sixdpose.fileio`). The output directory is shared (a figures directory, a run
directory), so the files are claimed one by one: an existing file of that name is replaced only if it is
a table of ours (recognised by its first line), otherwise the evaluation is refused before any work.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
from pathlib import Path

import numpy as np

from ..artifacts.predictions import (
    check_predictions_dataset,
    read_coco_results,
    read_predictions,
    read_predictions_meta,
)
from ..artifacts.tables import tex_escape
from ..datasets.base import DatasetError
from ..datasets.geometry import mask_box
from ..datasets.readers import open_dataset
from ..errors import OutputError
from ..fileio import atomic_write_text, claim_output_file
from .data import ClassMap
from .infer import coco_image_id, encode_rle

log = logging.getLogger("sixdpose.segmentation")

METRICS = ("AP", "AP50", "AP75")
#: The columns of ``seg_ap<tag>.csv`` (its header line) and the first line of ``seg_ap<tag>.tex``: an
#: existing file is recognised as ours by them.
CSV_COLUMNS = ["obj_id", "name", "n_gt"] + [f"{t}_{m}" for t in ("mask", "box") for m in METRICS]
TEX_FIRST_LINE = r"\begin{tabular}{lr|rrr|rrr}"


def coco_ground_truth(samples, classes: ClassMap) -> tuple[dict, dict]:
    """COCO ground-truth dict of an iterable of :class:`~sixdpose.datasets.Sample`.

    Returns:
        ``(coco_dict, stats)`` with stats ``{"images", "instances", "empty_masks", "non_class"}``.
    Raises:
        DatasetError: an instance has no mask.
    """
    images, anns = [], []
    stats = {"images": 0, "instances": 0, "empty_masks": 0, "non_class": 0}
    for s in samples:
        H, W = s.rgb.shape[:2]
        iid = coco_image_id(s.scene_id, s.im_id)
        images.append(
            {"id": iid, "width": int(W), "height": int(H), "scene_id": int(s.scene_id), "im_id": int(s.im_id)}
        )
        stats["images"] += 1
        for inst in s.instances:
            if classes.label_of(inst.obj_id) is None:
                stats["non_class"] += 1
                continue
            if inst.mask is None:
                raise DatasetError(
                    f"scene {s.scene_id} image {s.im_id}: instance of obj_id {inst.obj_id} has no mask; "
                    "segmentation AP needs visible masks"
                )
            npix = int(np.count_nonzero(inst.mask))
            if npix == 0:
                stats["empty_masks"] += 1
                continue
            box = mask_box(inst.mask)
            assert box is not None  # npix > 0
            v0, v1, u0, u1 = box
            anns.append({
                "id": len(anns) + 1,
                "image_id": iid,
                "category_id": int(inst.obj_id),
                "segmentation": encode_rle(inst.mask),
                "area": float(npix),
                "bbox": [float(u0), float(v0), float(u1 - u0), float(v1 - v0)],
                "iscrowd": 0,
            })
            stats["instances"] += 1
    if stats["empty_masks"]:
        log.info("left %d instance(s) with an empty mask out of the ground truth", stats["empty_masks"])
    cats = [{"id": i, "name": n} for i, n in zip(classes.obj_ids, classes.names, strict=True)]
    return {"images": images, "annotations": anns, "categories": cats}, stats


def _quiet():
    return contextlib.redirect_stdout(io.StringIO())


def coco_evaluate(gt: dict, results: list[dict], classes: ClassMap) -> dict:
    """Mask and box AP of ``results`` (COCO result dicts with RLE ``segmentation``) against ``gt``.

    Returns:
        ``{"overall": {"mask": {AP, AP50, AP75}, "box": {...}}, "per_class": [{obj_id, name, n_gt,
        mask_AP, mask_AP50, mask_AP75, box_AP, ...}], "n_images", "n_gt", "n_det"}``; AP values in
        [0, 1], NaN for a class without ground truth.
    """
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    with _quiet():
        coco_gt = COCO()
        coco_gt.dataset = json.loads(json.dumps(gt))
        coco_gt.createIndex()
    image_ids = {im["id"] for im in gt["images"]}
    results = [r for r in results if r["image_id"] in image_ids]
    n_gt = {c: 0 for c in classes.obj_ids}
    for a in gt["annotations"]:
        n_gt[a["category_id"]] += 1
    out = {
        "overall": {},
        "per_class": [],
        "n_images": len(image_ids),
        "n_gt": sum(n_gt.values()),
        "n_det": len(results),
    }
    per = {c: {} for c in classes.obj_ids}
    for iou_type, tag in (("segm", "mask"), ("bbox", "box")):
        if not results or not gt["annotations"]:
            vals = {m: (0.0 if gt["annotations"] else math.nan) for m in METRICS}
            out["overall"][tag] = vals
            for c in classes.obj_ids:
                for m in METRICS:
                    per[c][f"{tag}_{m}"] = 0.0 if n_gt[c] else math.nan
            continue
        with _quiet():
            coco_dt = coco_gt.loadRes([dict(r) for r in results])
            ev = COCOeval(coco_gt, coco_dt, iou_type)
            ev.params.imgIds = sorted(image_ids)
            ev.evaluate()
            ev.accumulate()
            ev.summarize()
        st = ev.stats
        out["overall"][tag] = {"AP": _nan(st[0]), "AP50": _nan(st[1]), "AP75": _nan(st[2])}
        prec = ev.eval["precision"]  # [T, R, K, A, M]
        iou_thr = ev.params.iouThrs
        for k, c in enumerate(ev.params.catIds):
            p_all = prec[:, :, k, 0, -1]
            per[c][f"{tag}_AP"] = _mean_valid(p_all)
            per[c][f"{tag}_AP50"] = _mean_valid(prec[np.argmin(np.abs(iou_thr - 0.5)), :, k, 0, -1])
            per[c][f"{tag}_AP75"] = _mean_valid(prec[np.argmin(np.abs(iou_thr - 0.75)), :, k, 0, -1])
    names = dict(zip(classes.obj_ids, classes.names, strict=True))
    for c in classes.obj_ids:
        out["per_class"].append({"obj_id": c, "name": names[c], "n_gt": n_gt[c], **per[c]})
    absent = [c for c in classes.obj_ids if n_gt[c] == 0]
    if absent:
        log.warning(
            "class(es) without ground truth in the evaluated images (AP undefined, excluded from the mean): %s",
            ", ".join(f"{c} ({names[c]})" for c in absent),
        )
    return out


def _nan(x: float) -> float:
    return math.nan if x < 0 else float(x)


def _mean_valid(p: np.ndarray) -> float:
    v = p[p > -1]
    return float(np.mean(v)) if v.size else math.nan


def open_segmented(data: str | Path, pred_dir: str | Path):
    """Open the dataset (split) that ``sixdpose segment`` wrote ``pred_dir`` from.

    Returns:
        ``(dataset, meta, index)`` with ``meta`` the prediction directory's ``meta.json`` and ``index``
        mapping ``(scene_id, im_id)`` to a dataset index.
    Raises:
        DatasetError: ``pred_dir`` has no ``meta.json``. PredictionError: ``meta.json`` is corrupt or
            lacks ``classes`` / ``images``, or the masks were predicted on another dataset.
    """
    meta_path = Path(pred_dir) / "meta.json"
    if not meta_path.is_file():
        raise DatasetError(f"{meta_path}: not a prediction directory of `sixdpose segment` (no meta.json)")
    meta = read_predictions_meta(pred_dir, required=("classes", "images"))
    ds = open_dataset(data, split=meta.get("split") or "test")
    check_predictions_dataset(pred_dir, ds, meta)
    index = {tuple(map(int, k)): i for i, k in enumerate(ds.keys())}
    return ds, meta, index


def evaluate(data: str | Path, pred_dir: str | Path, out_dir: str | Path | None = None, *, tag: str = "",
             progress: bool = False) -> dict:
    """Evaluate the predictions of ``sixdpose segment`` against the ground truth of ``data``.

    The evaluated images are those listed in ``PRED_DIR/meta.json`` (all images that were segmented,
    including those with no detection); the classes are the checkpoint's.

    Args:
        data: the dataset directory that was segmented.
        pred_dir: output of :func:`~.infer.segment`.
        out_dir: where to write ``seg_ap<tag>.csv`` / ``.tex`` (e.g. ``figures/``); ``None``: no files.
        tag: suffix of the file names, e.g. ``"_smoke"``.
        progress: a progress bar over the ground-truth images read.
    Returns:
        The dict of :func:`coco_evaluate` (plus ``files`` when written).
    Raises:
        DatasetError: missing/malformed predictions, or images of ``meta.json`` not in the dataset.
        OutputError: ``out_dir`` is a file, or holds a ``seg_ap<tag>`` file that is not ours (checked
            before any work; nothing is written).
    """
    if out_dir is not None:
        claim_tables(out_dir, tag)
    pred_dir = Path(pred_dir)
    ds, meta, index = open_segmented(data, pred_dir)
    classes = ClassMap.from_list(meta["classes"])
    classes.check_compatible(ds)
    wanted = [tuple(im[:2]) for im in meta["images"]]
    missing = [k for k in wanted if k not in index]
    if missing:
        raise DatasetError(f"{data}: {len(missing)} segmented image(s) are not in the dataset (first {missing[0]})")
    from tqdm import tqdm

    samples = (ds[index[k]] for k in tqdm(wanted, desc="eval-seg", unit="img", disable=not progress))
    gt, stats = coco_ground_truth(samples, classes)
    results = read_coco_results(pred_dir)
    if results is None:  # rebuild from the npz files
        results = []
        for s, i in wanted:
            for d in read_predictions(pred_dir, s, i):
                m, lab, sc = d.mask, d.obj_id, d.score
                box = mask_box(m)
                v0, v1, u0, u1 = box if box is not None else (0, 0, 0, 0)  # an empty mask: a 0 x 0 box at 0
                bbox = [float(u0), float(v0), float(u1 - u0), float(v1 - v0)]
                results.append({"image_id": coco_image_id(s, i), "category_id": int(lab),
                                "segmentation": encode_rle(m), "bbox": bbox, "score": float(sc)})
    metrics = coco_evaluate(gt, results, classes)
    metrics["gt_stats"] = stats
    if out_dir is not None:
        metrics["files"] = [str(p) for p in write_tables(metrics, out_dir, tag=tag)]
    return metrics


def table_paths(out_dir: str | Path, tag: str = "") -> tuple[Path, Path]:
    """The two files of :func:`write_tables`: ``out_dir/seg_ap<tag>.csv`` and ``.tex``."""
    out_dir = Path(out_dir)
    return out_dir / f"seg_ap{tag}.csv", out_dir / f"seg_ap{tag}.tex"


def claim_tables(out_dir: str | Path, tag: str = "") -> None:
    """Check that the tables of :func:`write_tables` may be written into ``out_dir`` (nothing is written).

    Accepted: a directory that does not exist yet or is writable, where ``seg_ap<tag>.csv`` / ``.tex`` are
    absent or earlier tables of ours (their first lines are :data:`CSV_COLUMNS` / :data:`TEX_FIRST_LINE`).

    Raises:
        OutputError: ``out_dir`` is a file, or one of the two files exists and is not ours.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise OutputError(f"{out_dir}: exists and is not a directory (the output directory of the AP tables)")
    csv_path, tex_path = table_paths(out_dir, tag)
    claim_output_file(csv_path, ",".join(CSV_COLUMNS))
    claim_output_file(tex_path, TEX_FIRST_LINE)


def write_tables(metrics: dict, out_dir: str | Path, tag: str = "") -> list[Path]:
    """Write the AP table of :func:`coco_evaluate` as CSV and LaTeX into ``out_dir``, atomically.

    Rows: one per class and a final ``all`` row; columns mask AP/AP50/AP75 and box AP/AP50/AP75 in
    percent (CSV: fractions with 4 decimals; LaTeX: percent with 1 decimal, ``--`` for undefined).

    Raises:
        OutputError: see :func:`claim_tables` (checked before either file is written).
    """
    claim_tables(out_dir, tag)
    csv_path, tex_path = table_paths(out_dir, tag)
    cols = CSV_COLUMNS[3:]
    rows = [dict(r) for r in metrics["per_class"]]
    overall = {"obj_id": "", "name": "all", "n_gt": metrics["n_gt"]}
    for t in ("mask", "box"):
        for m in METRICS:
            overall[f"{t}_{m}"] = metrics["overall"][t][m]
    rows.append(overall)
    buf = io.StringIO(newline="")
    w = csv.writer(buf, lineterminator="\r\n")
    w.writerow(CSV_COLUMNS)
    for r in rows:
        w.writerow([r["obj_id"], r["name"], r["n_gt"]] + [_fmt(r[c], 4, 1.0, "nan") for c in cols])

    lines = [
        TEX_FIRST_LINE,
        r"\hline",
        r" & & \multicolumn{3}{c|}{mask} & \multicolumn{3}{c}{box} \\",
        r"Object & $N_{gt}$ & AP & AP$_{50}$ & AP$_{75}$ & AP & AP$_{50}$ & AP$_{75}$ \\",
        r"\hline",
    ]
    for r in rows:
        if r["name"] == "all":
            lines.append(r"\hline")
        vals = " & ".join(_fmt(r[c], 1, 100.0, "--") for c in cols)
        lines.append(f"{tex_escape(r['name'])} & {r['n_gt']} & {vals} \\\\")
    lines += [r"\hline", r"\end{tabular}", ""]
    atomic_write_text(csv_path, buf.getvalue())
    atomic_write_text(tex_path, "\n".join(lines))
    return [csv_path, tex_path]


def _fmt(x: float, nd: int, scale: float, nan: str) -> str:
    return nan if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x * scale:.{nd}f}"
