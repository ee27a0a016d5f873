"""How well a dense-head pose run fits its object coordinates, per object, against a constant baseline.

For every instance of the frames read (GT masks, at least ``--min-px`` visible pixels) this builds the
network's input as ``predict-pose`` does (:func:`sixdpose.pose.data.extract_instance`), runs the network
once and compares its per-point object coordinates with the ground truth's (the best of the object's
symmetric candidates, :func:`sixdpose.pose.dense.coordinate_targets`; with shape flips the canonical turn's,
:func:`sixdpose.pose.dense.canonical_flip`, and whether the run names it: by its flip classifier or, for
a run without the CNN, by the model's colours on the true canonical pose). It prints per object
the median over instances of the mean point error (mm), and the same for a network that would answer the
model-box centre for every point (the error of knowing nothing but the class). A run whose error is not far
below that baseline on its own training frames is underfitting, whatever its pose accuracy.

    python benchmarks/dense_coordinates.py --pose dense2_e12=runs/cpu/pose_ycbv_dense_e12 \\
        --data generated=data/ycbv --data real=../shared/data/ycbv_sample@train_real --min-px 0 \\
        [--result dense_coordinates]

``--data`` must hold models of the run's objects. Prints one table per run and dataset; ``--result NAME``
also writes them as ``results/NAME.json`` (rows: run, data, obj_id, n, network_mm, constant_mm, ratio,
flip_right); ``--keep`` keeps that file's rows of the runs not measured this time.
"""

from __future__ import annotations

import argparse
import collections

import numpy as np
import torch

from sixdpose.datasets.readers import open_dataset
from sixdpose.pose.data import Frame, collate_frames, extract_instance
from sixdpose.pose.dense import Symmetry, canonical_flip, coordinate_targets, model_symmetry, shape_flips
from sixdpose.pose.infer import Estimator


def measure(pose: str, data: str, split: str, images: int, min_px: int, seed: int = 0) -> list[dict]:
    """One row per object of the run ``pose`` on ``images`` frames of ``data``: ``n`` instances, ``network_mm``
    and ``constant_mm`` (median over instances of the mean point error, the network's and the
    constant-centre answer's), their ``ratio``, and ``flip_right`` (``right/instances`` with shape flips: the
    turn the run names, by its classifier or, for a run naming turns by the model's colours
    (``flip_choice``), by those colours given the true canonical pose)."""
    ds = open_dataset(data, split)
    est = Estimator(pose, reader=ds, device="cpu")
    net, cfg = est.net, est.cfg
    if cfg.head != "dense":
        raise SystemExit(f"{pose}: head={cfg.head!r}, this measures the dense head only")
    keys = ds.keys()
    keys = keys[:: max(1, len(keys) // max(images, 1))][:images]
    syms: dict[int, Symmetry] = {}
    flips: dict[int, Symmetry] = {}
    per_obj: dict[int, list] = collections.defaultdict(list)
    rng = np.random.default_rng(seed)
    for key in keys:
        s = ds.load(key)
        insts, gts = [], []
        for k, o in enumerate(s.instances):
            if o.obj_id not in est.class_index or o.mask is None or int(o.mask.sum()) < min_px:
                continue
            if o.obj_id not in syms:
                syms[o.obj_id] = model_symmetry(ds.model(o.obj_id))
            inst = extract_instance(s.rgb, s.depth, s.K, o.mask, o.obj_id, crop=cfg.crop, margin=cfg.crop_margin,
                                    num_points=cfg.num_points, min_points=cfg.min_points, rng=rng, index=k,
                                    depth_band=float(ds.model(o.obj_id).diameter), keep_points=est.colour_flips)
            if not isinstance(inst, str):
                insts.append(inst)
                gts.append(o)
        if not insts:
            continue
        b = collate_frames([Frame(None, insts)], est.class_index)
        with torch.no_grad():
            out = net(b["images"], b["img_index"], b["choose"], b["cloud"], b["obj_index"])
        coords = out["coords"].double().numpy()
        for j, (inst, o) in enumerate(zip(insts, gts, strict=True)):
            ci = est.class_index[o.obj_id]
            n_flips = int(net.flip_n[ci]) if "flip_logit" in out else 1
            right = None
            if n_flips > 1:
                if o.obj_id not in flips:  # the run's turns; with this reader's model's axis when they agree
                    stored = Symmetry(net.flip_R[ci, :n_flips].double().numpy(),
                                      net.flip_t[ci, :n_flips].double().numpy())
                    found = shape_flips(ds.model(o.obj_id), cfg.flips)
                    same = len(found.R) == n_flips and np.allclose(found.R, stored.R, atol=1e-4)
                    flips[o.obj_id] = found if same else stored
                fl = flips[o.obj_id]
                fr = out["frame"][j].double().numpy() if "frame" in out else None  # input_frame=pca
                d = canonical_flip(o.R, fl, fr)
                tg = coordinate_targets(inst.cloud, o.R, o.t, fl)[d:d + 1]
                named = None
                if est.colour_flips:  # the turn named by the model's colours, from the true canonical pose
                    named = est._colour_flip(inst, o.R @ fl.R[d], o.R @ fl.t[d] + o.t, ci)
                right = (int(out["flip_logit"][j].argmax()) if named is None else named) == d
            else:
                tg = coordinate_targets(inst.cloud, o.R, o.t, syms[o.obj_id])
            err = np.linalg.norm(coords[j][None] - tg, axis=2).mean(axis=1).min()
            base = np.linalg.norm(net.centres[ci].double().numpy()[None, None] - tg, axis=2).mean(axis=1).min()
            per_obj[o.obj_id].append((1000 * err, 1000 * base, right))
    rows = []
    for oid, v in sorted(per_obj.items()):
        e, b = float(np.median([r[0] for r in v])), float(np.median([r[1] for r in v]))
        fr = [r[2] for r in v if r[2] is not None]
        rows.append({"obj_id": oid, "n": len(v), "network_mm": round(e, 1), "constant_mm": round(b, 1),
                     "ratio": round(e / b, 2), "flip_right": f"{sum(fr)}/{len(fr)}" if fr else "-"})
    return rows


def main() -> None:
    """Parse the arguments, measure every run on every dataset, print the tables (and write the artifact)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--pose", action="append", required=True, metavar="LABEL=RUN",
                    help="a train-pose run with head=dense (repeatable)")
    ap.add_argument("--data", action="append", required=True, metavar="LABEL=PATH[@SPLIT]",
                    help="a dataset (synthetic layout, or BOP root @ split), repeatable")
    ap.add_argument("--images", type=int, default=40, help="frames read, evenly spaced over each dataset")
    ap.add_argument("--min-px", type=int, default=400, help="instances with fewer visible pixels are skipped")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--result", default=None, help="also write results/<RESULT>.json (one row per run, data, object)")
    ap.add_argument("--results-dir", default="results")
    ap.add_argument("--keep", action="store_true",
                    help="with --result: keep the rows already there of the runs not given this time (placed first)")
    a = ap.parse_args()
    table = []
    for spec in a.pose:
        label, _, run = spec.partition("=")
        for dspec in a.data:
            dlabel, _, path = dspec.partition("=")
            path, _, split = path.partition("@")
            rows = measure(run, path, split or "test", a.images, a.min_px, a.seed)
            print(f"{label} ({run}) on {dlabel} ({path}, {a.images} frames): mean point error of the object "
                  "coordinates, median over instances (mm)")
            print("obj_id    n  network  constant-centre  ratio  flip right")
            for r in rows:
                print(f"{r['obj_id']:6d} {r['n']:4d} {r['network_mm']:8.1f} {r['constant_mm']:16.1f} {r['ratio']:6.2f}"
                      f"  {r['flip_right']}")
            table += [{"run": label, "data": dlabel, **r} for r in rows]
    if a.result:
        from sixdpose.artifacts.results import earlier_rows, write_result

        if a.keep:
            table = earlier_rows(a.result, table, results_dir=a.results_dir) + table

        print(write_result(a.result, table, results_dir=a.results_dir,
                           units={"network_mm": "mm", "constant_mm": "mm", "n": "instances"},
                           description="dense head: mean point error of the per-point object coordinates "
                                       "(median over instances) beside answering the model-box centre, and "
                                       f"the flip classifier; GT masks, >= {a.min_px} px, {a.images} frames "
                                       "per dataset", notes="python benchmarks/dense_coordinates.py"))


if __name__ == "__main__":
    main()
