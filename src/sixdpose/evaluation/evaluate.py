"""ADD(-S) accuracy and timing of a BOP results CSV against a dataset (``sixdpose evaluate``).

Protocol (paper section V-A; matching as in the BOP toolkit):

* GT instances counted: every annotated instance whose visible mask has at least ``min_px`` pixels
  (400 by default; instances with unknown pixel count are counted).
* Per image and object, only the ``n`` best-scoring estimates are considered, ``n`` = number of counted
  GT instances of that object in the image; estimates with score <= 0 are "no estimate".
* Greedy matching in decreasing score: an estimate is matched to the still unmatched GT instance of
  its object with the smallest ADD(-S) error, if that error is below ``threshold`` x diameter; a
  matched GT instance counts as correct. ADD-S for symmetric objects, ADD otherwise (eq. 4).
* Timing: frames per second = images in the results / sum of their per-image times (each image's
  time once); instances per second = estimates / the same total. Times exclude disk reads.
"""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..datasets.base import DatasetError
from . import metrics


@dataclass
class Estimate:
    """One results row: R (3, 3), t (3,) metres, score, time (s, per image)."""

    scene_id: int
    im_id: int
    obj_id: int
    score: float
    R: np.ndarray
    t: np.ndarray
    time: float


def load_results(path: str | Path) -> list[Estimate]:
    """Read a BOP results CSV (``scene_id,im_id,obj_id,score,R,t,time``; t in mm) into metres.

    Raises:
        DatasetError: missing file, missing column or a malformed row (the message names the line).
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: results file not found")
    out = []
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        need = {"scene_id", "im_id", "obj_id", "score", "R", "t", "time"}
        missing = need - set(reader.fieldnames or [])
        if missing:
            raise DatasetError(f"{path}: missing column(s) {', '.join(sorted(missing))}")
        for line, row in enumerate(reader, start=2):
            try:
                R = np.array([float(v) for v in row["R"].split()], dtype=np.float64).reshape(3, 3)
                t = np.array([float(v) for v in row["t"].split()], dtype=np.float64).reshape(3) / 1000.0
                out.append(Estimate(int(row["scene_id"]), int(row["im_id"]), int(row["obj_id"]), float(row["score"]), R, t, float(row["time"])))
            except (ValueError, TypeError, AttributeError) as e:
                raise DatasetError(f"{path}: line {line}: malformed row ({e})") from None
    return out


@dataclass
class EvalResult:
    """Outcome of :func:`evaluate`.

    Attributes:
        per_object: obj_id -> dict(name, n_gt, n_correct, accuracy (%)).
        accuracy: % over all counted GT instances. mean_object_accuracy: mean of per-object %.
        n_gt, n_correct: counts. fps, instances_per_s, n_images, n_estimates, total_time: timing.
        records: per counted GT instance: (scene_id, im_id, obj_id, index in ``Sample.instances``,
            ADD(-S) error (m) of its match or of the nearest estimate, or nan, correct).
    """

    per_object: dict
    accuracy: float
    mean_object_accuracy: float
    n_gt: int
    n_correct: int
    fps: float
    instances_per_s: float
    n_images: int
    n_estimates: int
    total_time: float
    records: list = field(default_factory=list)

    def summary(self) -> dict:
        """The scalar fields as a dict (JSON-serialisable)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("per_object", "records")}


def evaluate(dataset, estimates: list[Estimate], min_px: int = 400, threshold: float = 0.1, progress: bool = False,
             images=None) -> EvalResult:
    """Score ``estimates`` against ``dataset`` (see the module docstring for the protocol).

    Args:
        dataset: a reader (:func:`~sixdpose.datasets.base.open_dataset`).
        estimates: rows of :func:`load_results`, or any objects with the same attributes
            (``scene_id, im_id, obj_id, score, R, t, time``), such as the registration stage's result
            rows. min_px: GT visibility threshold (pixels).
        threshold: fraction of the diameter (0.1).
        images: the ``(scene_id, im_id)`` keys evaluated; an image without estimates counts its GT
            instances as failures. ``None``: the images that appear in the results (every image if
            there are none), which suits GT-mask runs on a subset; with predicted masks an image where
            nothing was detected has no rows, so pass the registered images (or ``dataset.keys()``).
    Returns:
        :class:`EvalResult`.
    """
    from tqdm import tqdm

    by_img: dict[tuple[int, int], list[Estimate]] = defaultdict(list)
    for e in estimates:
        by_img[(e.scene_id, e.im_id)].append(e)
    keys = dataset.keys()
    known = set(keys)
    unknown = [k for k in by_img if k not in known]
    if unknown:
        raise DatasetError(f"results refer to image(s) not in the dataset, e.g. scene {unknown[0][0]} image {unknown[0][1]}")
    names = dataset.object_ids
    n_gt_obj: dict[int, int] = defaultdict(int)
    n_ok_obj: dict[int, int] = defaultdict(int)
    records = []
    # only images with results are evaluated when the results cover a subset (e.g. --limit runs)
    if images is not None:
        want = {(int(a), int(b)) for a, b in images}
        missing = sorted(want - known)
        if missing:
            raise DatasetError(f"images not in the dataset, e.g. scene {missing[0][0]} image {missing[0][1]}")
        eval_keys = [k for k in keys if k in want]
    else:
        eval_keys = [k for k in keys if k in by_img] if by_img else keys
    pos = {k: i for i, k in enumerate(keys)}
    for key in tqdm(eval_keys, desc="evaluate", unit="img", disable=not progress):
        sample = _load_gt(dataset, pos[key])
        gts = [g for g in sample.instances if g.px_visib < 0 or g.px_visib >= min_px]
        ests = by_img.get(key, [])
        for oid in sorted({g.obj_id for g in gts}):
            g_o = [g for g in gts if g.obj_id == oid]
            e_o = sorted((e for e in ests if e.obj_id == oid and e.score > 0), key=lambda e: -e.score)[: len(g_o)]
            model = dataset.model(oid)
            err = np.array([[metrics.add_s(e.R, e.t, g.R, g.t, model.points, model.symmetric) for g in g_o] for e in e_o]).reshape(len(e_o), len(g_o))
            matched = np.full(len(g_o), np.nan)
            for i in range(len(e_o)):
                cand = [(err[i, j], j) for j in range(len(g_o)) if math.isnan(matched[j]) and err[i, j] < threshold * model.diameter]
                if cand:
                    e_min, j = min(cand)
                    matched[j] = e_min
            for j, g in enumerate(g_o):
                ok = not math.isnan(matched[j])
                best = matched[j] if ok else (float(err[:, j].min()) if len(e_o) else math.nan)
                records.append((key[0], key[1], oid, sample.instances.index(g), best, ok))
                n_gt_obj[oid] += 1
                n_ok_obj[oid] += int(ok)
    per_object = {
        oid: {"name": names.get(oid, str(oid)), "n_gt": n_gt_obj[oid], "n_correct": n_ok_obj[oid], "accuracy": 100.0 * n_ok_obj[oid] / n_gt_obj[oid]}
        for oid in sorted(n_gt_obj)
    }
    n_gt = sum(n_gt_obj.values())
    n_ok = sum(n_ok_obj.values())
    img_time = {k: max(e.time for e in v) for k, v in by_img.items()}
    total = float(sum(t for t in img_time.values() if t >= 0))
    n_est = sum(len(v) for v in by_img.values())
    return EvalResult(
        per_object=per_object,
        accuracy=100.0 * n_ok / n_gt if n_gt else float("nan"),
        mean_object_accuracy=float(np.mean([v["accuracy"] for v in per_object.values()])) if per_object else float("nan"),
        n_gt=n_gt,
        n_correct=n_ok,
        fps=len(img_time) / total if total > 0 else float("nan"),
        instances_per_s=n_est / total if total > 0 else float("nan"),
        n_images=len(img_time),
        n_estimates=n_est,
        total_time=total,
        records=records,
    )


def _load_gt(dataset, index: int):
    """GT of one image, skipping the mask PNGs when the reader allows it (``px_visib`` comes from the
    annotations)."""
    key = dataset.keys()[index] if not hasattr(dataset, "_keys") else dataset._keys[index]
    if hasattr(dataset, "load_key"):
        return dataset.load_key(*key, with_masks=False)
    if hasattr(dataset, "load"):
        try:
            return dataset.load(key[1], with_masks=False)
        except TypeError:
            pass
    return dataset[index]


def write_tables(res: EvalResult, out_dir: str | Path, label: str = "method") -> dict[str, Path]:
    """Write ``add_s_per_object.csv``, ``add_s.tex``, ``timing.csv`` and ``summary.json`` to ``out_dir``.

    Returns:
        name -> path of each written file.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    p = out / "add_s_per_object.csv"
    with open(p, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["obj_id", "name", "n_gt", "n_correct", "add_s_accuracy"])
        for oid, v in res.per_object.items():
            w.writerow([oid, v["name"], v["n_gt"], v["n_correct"], f"{v['accuracy']:.2f}"])
        w.writerow(["all", "mean over instances", res.n_gt, res.n_correct, f"{res.accuracy:.2f}"])
        w.writerow(["objects", "mean over objects", "", "", f"{res.mean_object_accuracy:.2f}"])
    paths["per_object"] = p
    p = out / "add_s.tex"
    lines = [
        "\\begin{tabular}{lrr}",
        "\\toprule",
        "Object & GT instances & ADD(-S) (\\%) \\\\",
        "\\midrule",
    ]
    for oid, v in res.per_object.items():
        lines.append(f"{_tex(v['name'])} & {v['n_gt']} & {v['accuracy']:.2f} \\\\")
    lines += [
        "\\midrule",
        f"Mean (instances) & {res.n_gt} & {res.accuracy:.2f} \\\\",
        f"Mean (objects) &  & {res.mean_object_accuracy:.2f} \\\\",
        "\\bottomrule",
        "\\end{tabular}",
        f"% {label}: FPS {res.fps:.3f}, instances/s {res.instances_per_s:.3f}",
    ]
    p.write_text("\n".join(lines) + "\n")
    paths["latex"] = p
    p = out / "timing.csv"
    with open(p, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["method", "n_images", "n_estimates", "total_time_s", "fps", "instances_per_s"])
        w.writerow([label, res.n_images, res.n_estimates, f"{res.total_time:.4f}", f"{res.fps:.4f}", f"{res.instances_per_s:.4f}"])
    paths["timing"] = p
    p = out / "summary.json"
    p.write_text(json.dumps(dict(res.summary(), label=label), indent=1))
    paths["summary"] = p
    return paths


def _tex(s: str) -> str:
    return s.replace("\\", "\\textbackslash{}").replace("_", "\\_").replace("&", "\\&").replace("%", "\\%")


def write_method_table(rows: list[dict], columns: list[str], csv_path: str | Path, tex_path: str | Path | None = None) -> None:
    """Write a small table (list of dicts) as CSV and, optionally, as a LaTeX ``tabular``
    (used for the hybrid rows of Tables II and III)."""
    csv_path = Path(csv_path)
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([r[c] for c in columns])
    if tex_path is not None:
        def fmt(v):
            return f"{v:.2f}" if isinstance(v, float) else _tex(str(v))

        lines = ["\\begin{tabular}{" + "l" * 2 + "r" * (len(columns) - 2) + "}", "\\toprule",
                 " & ".join(_tex(c) for c in columns) + " \\\\", "\\midrule"]
        lines += [" & ".join(fmt(r[c]) for c in columns) + " \\\\" for r in rows]
        lines += ["\\bottomrule", "\\end{tabular}"]
        Path(tex_path).write_text("\n".join(lines) + "\n")
