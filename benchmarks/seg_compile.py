"""The compiled Mask R-CNN backbone against the eager one, end to end with a pose run, in one process.

Usage::

    python benchmarks/seg_compile.py --seg runs/cpu/seg_mbv3l_e4 [--pose runs/cpu/pose_dense]
                                     [--data data/test] [--frames 40] [--passes 6] [--threads N]
                                     [--results-dir results] [--result-name seg_compile_cpu] [--no-result]

One process holds two ``Segmenter`` of ``--seg``: the eager network (``optimise=False``) and the one whose
backbone :func:`sixdpose.segmentation.infer.optimise_backbone` compiled. Every frame is first run once
through each (untimed: first-call allocations and the objects' onboarding). Then they take turns, one
whole pass over the frames each, ``--passes`` times, the order reversed every other round. A pass is what
``benchmarks/pose.py`` times end to end: segmentation keeping detections scoring >= ``MIN_DETECTION_SCORE``,
then the pose stage on those detections. A shared machine's slow and fast spells therefore fall on both
variants alike. Separate processes, minutes apart, were seen to differ by a fifth on this 2-core machine
with no code change.

Reported per variant: the mean segmentation and pose milliseconds per frame over its passes, the frame rate
from their sum, and the slowest and fastest pass. Also reported: whether the two gave the same detections
on every frame (labels equal, scores within 1e-4, masks differing in at most 0.1 % of the pixels).
One row per variant is printed and written as the result artifact ``results/<name>.json`` (+ ``.csv``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command  # noqa: E402
from sixdpose.options import Int  # noqa: E402


def same_detections(a: dict, b: dict) -> bool:
    """Whether two ``Segmenter.predict`` outputs of one image agree: the same labels, scores within 1e-4,
    masks of the same shape differing in at most 0.1 % of their pixels."""
    if not np.array_equal(a["labels"], b["labels"]) or a["masks"].shape != b["masks"].shape:
        return False
    if not np.allclose(a["scores"], b["scores"], atol=1e-4):
        return False
    return int((a["masks"] != b["masks"]).sum()) <= 0.001 * max(a["masks"].size, 1)


def compare(seg: str, pose: str, data: str, frames: int, passes: int) -> tuple[list[dict], bool]:
    """Rows ``{variant, seg_ms, pose_ms, e2e_ms, e2e_fps, e2e_fps_min, e2e_fps_max, passes, frames,
    detections_per_frame}`` for the eager and the compiled segmenter, and whether their detections agreed."""
    from sixdpose.artifacts.predictions import Detection
    from sixdpose.constants import MIN_DETECTION_SCORE
    from sixdpose.datasets import as_reader
    from sixdpose.pose.infer import Estimator
    from sixdpose.segmentation.infer import Segmenter

    path, _, split = data.partition("@")
    reader = as_reader(path, split=split or "test")
    samples = [reader.load(k, masks=False) for k in reader.keys()[:frames]]  # disk reads not timed
    est = Estimator(pose, None, iterations=0, device="cpu", reader=reader)
    variants = {"eager": Segmenter(seg, device="cpu", score_thresh=MIN_DETECTION_SCORE, optimise=False),
                "compiled": Segmenter(seg, device="cpu", score_thresh=MIN_DETECTION_SCORE, optimise=True)}
    if not variants["compiled"].optimised:
        raise RuntimeError(f"{seg}: the backbone could not be compiled (see the warning above)")

    def run(segm, sample):
        t0 = time.perf_counter()
        out = segm.predict([sample.rgb])[0]
        t1 = time.perf_counter()
        dets = [Detection(int(o), float(s), m) for o, s, m in zip(out["labels"], out["scores"], out["masks"],
                                                                     strict=True)]
        est.predict(sample, dets)
        return (t1 - t0, time.perf_counter() - t1), out

    first = {k: [run(v, s)[1] for s in samples] for k, v in variants.items()}  # warm-up and onboarding
    agree = all(same_detections(a, b) for a, b in zip(first["eager"], first["compiled"], strict=True))
    n_det = float(np.mean([len(o["labels"]) for o in first["compiled"]]))
    timed: dict[str, list[np.ndarray]] = {k: [] for k in variants}
    order = list(variants)
    for p in range(passes):
        for k in order if p % 2 == 0 else order[::-1]:
            timed[k].append(np.array([run(variants[k], s)[0] for s in samples]))
    rows = []
    for k, ps in timed.items():
        seg_ms = 1000 * float(np.mean([t[:, 0].mean() for t in ps]))
        pose_ms = 1000 * float(np.mean([t[:, 1].mean() for t in ps]))
        totals = [float(t.sum(axis=1).mean()) for t in ps]
        rows.append({"variant": k, "seg_ms": seg_ms, "pose_ms": pose_ms, "e2e_ms": seg_ms + pose_ms,
                     "e2e_fps": 1000.0 / (seg_ms + pose_ms), "e2e_fps_min": 1.0 / max(totals),
                     "e2e_fps_max": 1.0 / min(totals), "passes": passes, "frames": len(samples),
                     "detections_per_frame": n_det})
    return rows, agree


def main(argv=None) -> int:
    """Time both variants; print one row each and write the result artifact."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seg", required=True, help="a trained segmentation run (train-seg --out) or checkpoint")
    ap.add_argument("--pose", default="runs/cpu/pose_dense", help="a trained pose run (the dense head)")
    ap.add_argument("--data", default="data/test", help="DIR[@SPLIT] whose first --frames frames are timed")
    ap.add_argument("--frames", type=Int(1, 100_000), default=40, help="frames per pass")
    ap.add_argument("--passes", type=Int(1, 1000), default=6, help="timed passes per variant")
    ap.add_argument("--threads", type=Int(0, 1024), default=0, help="torch CPU threads (0: torch's default)")
    add_result_arguments(ap, "seg_compile_cpu", Path(__file__).resolve().parents[1] / "results")
    args = ap.parse_args(argv)
    import torch

    if args.threads:
        torch.set_num_threads(args.threads)
    rows, agree = compare(args.seg, args.pose, args.data, args.frames, args.passes)
    for r in rows:
        r["same_detections"] = agree
        print(json.dumps(r))
    save_from_args(args, rows, command=script_command(__file__, argv),
                   units={"seg_ms": "ms", "pose_ms": "ms", "e2e_ms": "ms", "e2e_fps": "frames/s",
                          "e2e_fps_min": "frames/s", "e2e_fps_max": "frames/s"},
                   description="Mask R-CNN with its backbone eager and compiled (optimise_backbone), end to end "
                               "with the dense head, passes interleaved in one process",
                   config={"seg": args.seg, "pose": args.pose, "data": args.data, "frames": args.frames,
                           "passes": args.passes, "threads": torch.get_num_threads()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
