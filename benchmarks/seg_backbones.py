"""Mask R-CNN backbones side by side: mask AP on the runs' held-out images and the time per image on this CPU.

Usage::

    python benchmarks/seg_backbones.py --runs runs/cpu/seg runs/cpu/seg_mbv3l [--data data/train]
                                       [--time-data data/test] [--frames 20] [--threads N]
                                       [--results-dir results] [--result-name seg_backbones_cpu] [--no-result]

For each trained segmentation run (``sixdpose train-seg``):

* **accuracy**: the run segments its own held-out images of ``--data`` (``segment --subset test``: the
  seeded 90/10 split of ``split.json``, never trained on; runs trained with the same seed on the same data
  hold out the same images, which is checked) and pycocotools scores them (COCO mask and box AP, AP50), as
  ``sixdpose eval-seg`` does; no test split is used to compare or choose;
* **time**: ``Segmenter.predict`` on the first ``--frames`` images of ``--time-data`` (loaded into memory
  first; the first also run once untimed, as ``benchmarks/segmentation.py`` times them), keeping the
  detections the pose stage uses (score >= ``MIN_DETECTION_SCORE``), as the end-to-end timing of
  ``benchmarks/pose.py`` does: milliseconds per image and detections per image;
* the backbone, its parameters and those of the whole network.

One row per run is printed and written as the result artifact ``results/<name>.json`` (+ ``.csv``).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command  # noqa: E402
from sixdpose.options import Int  # noqa: E402


def held_out_ap(run: Path, data: str, tmp: Path) -> dict:
    """COCO figures of ``run`` on its own held-out images of ``data`` (``segment --subset test``)."""
    from sixdpose.segmentation.evaluate import evaluate
    from sixdpose.segmentation.infer import segment

    out = tmp / run.name
    seg = segment(data, run, out, subset="test", progress=False)
    m = evaluate(data, out)
    return {"held_out_images": seg["images"], "mask_ap": 100 * m["overall"]["mask"]["AP"],
            "mask_ap50": 100 * m["overall"]["mask"]["AP50"], "box_ap": 100 * m["overall"]["box"]["AP"],
            "box_ap50": 100 * m["overall"]["box"]["AP50"]}


def time_per_image(run: Path, data: str, frames: int) -> dict:
    """Milliseconds per image of ``Segmenter.predict`` (detections scoring >= ``MIN_DETECTION_SCORE``), timed by
    ``benchmarks/segmentation.py``'s :func:`bench_device` (one image per call, the first also run untimed)."""
    import importlib.util

    from sixdpose.constants import MIN_DETECTION_SCORE
    from sixdpose.datasets import as_reader
    from sixdpose.segmentation.infer import Segmenter, optimise_backbone

    spec = importlib.util.spec_from_file_location("_bench_segmentation", Path(__file__).with_name("segmentation.py"))
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    path, _, split = data.partition("@")
    reader = as_reader(path, split=split or "test")
    rgbs = [reader.load(k, masks=False).rgb for k in reader.keys()[:frames]]
    seg = Segmenter(run, device="cpu", score_thresh=MIN_DETECTION_SCORE, optimise=False)
    # the parameters are counted on the eager network (compiling folds them into constants), then it is
    # compiled as the Segmenter does on the CPU by default
    n_body = sum(p.numel() for p in seg.model.backbone.body.parameters()) / 1e6
    n_all = sum(p.numel() for p in seg.model.parameters()) / 1e6
    seg.optimised = optimise_backbone(seg.model, seg.cfg)
    timing = bench.bench_device(seg, rgbs, batch_size=1, warmup=1)
    return {"backbone": seg.cfg.backbone, "backbone_params_m": n_body, "params_m": n_all, "compiled": seg.optimised,
            "ms_per_image": timing["ms_per_image"], "images_per_s": timing["images_per_s"],
            "detections_per_image": timing["detections"] / max(timing["images"], 1), "timed_images": timing["images"]}


def main(argv=None) -> int:
    """Score and time every run of ``--runs``; print one row each and write the result artifact."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="+", required=True, help="segmentation run directories (train-seg --out)")
    ap.add_argument("--data", default="data/train", help="the runs' training data (their held-out images are scored)")
    ap.add_argument("--time-data", default="data/test", help="DIR[@SPLIT] whose first --frames images are timed")
    ap.add_argument("--frames", type=Int(1, 100_000), default=20, help="images timed per run")
    ap.add_argument("--threads", type=Int(0, 1024), default=0, help="torch CPU threads (0: torch's default)")
    add_result_arguments(ap, "seg_backbones_cpu", Path(__file__).resolve().parents[1] / "results")
    args = ap.parse_args(argv)
    import torch

    if args.threads:
        torch.set_num_threads(args.threads)
    runs = [Path(r) for r in args.runs]
    for r in runs:
        if not (r / "split.json").is_file():
            print(f"{r}: not a segmentation run directory with split.json", file=sys.stderr)
            return 2
    splits = {json.dumps(json.loads((r / "split.json").read_text()).get("test"), sort_keys=True) for r in runs}
    if len(splits) != 1:
        print("the runs hold out different images (split.json differs): their AP would not compare", file=sys.stderr)
        return 2
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in runs:
            row = {"run": str(r)}
            row.update(time_per_image(r, args.time_data, args.frames))
            row.update(held_out_ap(r, args.data, Path(tmp)))
            rows.append(row)
            print(json.dumps(row))
    save_from_args(args, rows, command=script_command(__file__, argv),
                   units={"ms_per_image": "ms", "images_per_s": "images/s", "mask_ap": "%", "mask_ap50": "%",
                          "box_ap": "%", "box_ap50": "%", "backbone_params_m": "M", "params_m": "M"},
                   description="Mask R-CNN backbones: COCO AP on the runs' held-out training images, CPU time per "
                               "image keeping detections scoring >= 0.5",
                   config={"data": args.data, "time_data": args.time_data, "frames": args.frames,
                           "threads": torch.get_num_threads()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
