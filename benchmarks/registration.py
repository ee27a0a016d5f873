"""Benchmark the hybrid methods: ADD(-S) accuracy and instances/s on ONE core, for our ``default``
preset and for the plain Open3D pipeline with the paper's settings (``paper`` preset: full scene
cloud, 2 mm reference voxels, Open3D tutorial RANSAC criteria), in the same run, side by side.

Usage::

    python benchmarks/registration.py [--data data/val] [--split test] [--limit N] [--stride K]
        [--methods ransac,fgr,super4pcs] [--presets default,paper] [--paper-stride K]
        [--results-dir results] [--result-name registration_<data dir name>] [--no-result]

Without ``--data`` the fixed validation split is generated (if missing) with the generator's ``val``
profile (seed 100, 6 scenes x 20 views) into ``data/val``; the default ``--stride 5`` takes every 5th
image of it. The ``paper`` preset (full clouds, 2 mm models; several times slower) runs on every
``--paper-stride``-th image (default: 4 x ``--stride``), a subset of the same images; each row prints
its instance count. A BOP root works too.

The table is also written as the result artifact ``results/registration_<data dir name>.json`` (one row
per preset and method; :mod:`sixdpose.artifacts.results`), with the commit, date, hardware and command.
"""

from __future__ import annotations

import os

# one core: must be set before numpy / open3d start their thread pools
for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from sixdpose.constants import MIN_VISIBLE_PX  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="dataset (default: data/val, generated with the val profile)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--limit", type=int, default=None, help="only the first N images")
    ap.add_argument("--stride", type=int, default=5, help="only every N-th image (a fixed subset over all scenes)")
    ap.add_argument("--paper-stride", type=int, default=None,
                    help="image stride of the paper preset (default 4 x --stride: it is several times slower)")
    ap.add_argument("--methods", default="ransac,fgr,super4pcs")
    ap.add_argument("--presets", default="default,paper")
    ap.add_argument("--min-px", type=int, default=MIN_VISIBLE_PX)
    ap.add_argument("--csv", default=None, help="also write the table as CSV here")
    ap.add_argument("--symmetric-ids", default=None,
                    help="BOP only: comma-separated obj_ids treated as symmetric (for files without annotations)")
    from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command

    add_result_arguments(ap, None, Path(__file__).resolve().parents[1] / "results", "registration_<data dir name>")
    args = ap.parse_args(argv)

    from sixdpose.datasets import open_dataset
    from sixdpose.evaluation.evaluate import evaluate
    from sixdpose.registration.presets import get_preset
    from sixdpose.registration.runner import run_registration

    data = args.data
    if data is None:
        root = Path(__file__).resolve().parents[1]
        data = root / "data" / "val"
        from sixdpose.generation import ensure_dataset

        ensure_dataset(data, profile="val")
    kw = {"symmetric_ids": [int(x) for x in args.symmetric_ids.split(",")]} if args.symmetric_ids else {}
    ds = open_dataset(data, split=args.split, **kw)
    if args.result_name is None:
        args.result_name = "registration_" + Path(str(data)).name
    table = []
    for preset in args.presets.split(","):
        cfg = get_preset(preset)
        stride = (args.paper_stride or 4 * args.stride) if preset == "paper" else args.stride
        indices = range(0, len(ds), stride) if stride > 1 else None
        for method in args.methods.split(","):
            for icp in (False, True):
                t0 = time.perf_counter()
                rows = run_registration(ds, method, icp=icp, cfg=cfg, workers=1, limit=args.limit,
                                        min_px=args.min_px, progress=False, indices=indices)
                wall = time.perf_counter() - t0
                res = evaluate(ds, rows, min_px=args.min_px)
                table.append(
                    (
                        preset,
                        method + ("+icp" if icp else ""),
                        res.accuracy,
                        res.n_gt,
                        res.instances_per_s,
                        res.fps,
                        wall,
                        res.n_correct,
                    )
                )
                print(f"{preset:8s} {table[-1][1]:15s} ADD(-S) {res.accuracy:6.2f}%  ({res.n_correct}/{res.n_gt})  "
                      f"{table[-1][4]:7.2f} inst/s  {res.fps:6.2f} FPS  (wall {wall:.1f}s)", flush=True)
    print("\nmethod            " + "  ".join(f"{p:>31s}" for p in args.presets.split(",")))
    names = sorted({t[1] for t in table}, key=lambda n: [t[1] for t in table].index(n))
    for n in names:
        cells = []
        for p in args.presets.split(","):
            t = next(x for x in table if x[0] == p and x[1] == n)
            cells.append(f"{t[2]:6.2f}% (N={t[3]}) {t[4]:6.2f} inst/s")
        print(f"{n:16s}  " + "  ".join(f"{c:>31s}" for c in cells))
    if args.csv:
        from sixdpose.artifacts.tables import write_table

        cols = ["preset", "method", "add_s_accuracy", "n_gt", "instances_per_s_one_core", "fps", "wall_s"]
        write_table([dict(zip(cols, t, strict=False)) for t in table], cols, args.csv)
    cols = ["preset", "method", "add_s_accuracy", "n_gt", "instances_per_s_one_core", "fps", "wall_s", "n_correct"]
    save_from_args(
        args, [dict(zip(cols, t, strict=True)) for t in table], command=script_command(__file__, argv),
        units={"add_s_accuracy": "%", "n_gt": "GT instances", "n_correct": "GT instances",
               "instances_per_s_one_core": "instances/s", "fps": "frames/s", "wall_s": "s"},
        description=f"hybrid registration on one core, GT masks, >= {args.min_px} px: ADD(-S) < 0.1 d and instances/s "
                    f"per preset and method on {Path(str(data)).name} (stride {args.stride}, paper preset stride "
                    f"{args.paper_stride or 4 * args.stride})",
        config={"data": str(data), "split": args.split, "limit": args.limit, "stride": args.stride,
                "paper_stride": args.paper_stride or 4 * args.stride, "min_px": args.min_px,
                "symmetric_ids": args.symmetric_ids,
                "presets": {p: get_preset(p).to_dict() for p in args.presets.split(",")}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
