"""Parameter sweep of the hybrid methods on the VALIDATION split: each variant's ADD(-S) accuracy,
per-object accuracy and instances/s, one process per variant (``--jobs`` at a time, each on one
thread). This is how the ``default`` preset's values were chosen (``presets.py`` records the numbers).

Usage::

    python benchmarks/tune_registration.py --method ransac --icp --stride 5 \\
        --variant base: --variant it20k:ransac_max_iteration=20000 [--variant NAME:k=v,k=v ...] [--csv out.csv]
        [--results-dir results] [--result-name tune_<method>[_icp]] [--no-result]

A variant is ``NAME:`` followed by comma-separated ``field=value`` overrides of the ``default`` preset
(``--preset`` to start from another). Without ``--data`` the validation split is generated (if missing)
with the ``val`` profile into ``data/val``. Never point this at the test split. One row per variant is
also written as the result artifact ``results/tune_<method>[_icp].json``.
"""

from __future__ import annotations

import os

for _k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_k] = "1"

import argparse  # noqa: E402
import multiprocessing as mp  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

from sixdpose.constants import MIN_VISIBLE_PX  # noqa: E402


def _parse_variant(text: str) -> tuple[str, dict]:
    from sixdpose.config import parse_overrides

    name, _, rest = text.partition(":")
    return name, parse_overrides(filter(None, rest.split(",")))


def _run(job):
    data, split, method, icp, preset, name, kw, stride, min_px = job
    from sixdpose.datasets import open_dataset
    from sixdpose.evaluation.evaluate import evaluate
    from sixdpose.registration.presets import get_preset
    from sixdpose.registration.runner import run_registration

    cfg = get_preset(preset, **kw)
    ds = open_dataset(data, split=split)
    rows = run_registration(ds, method, icp=icp, cfg=cfg, workers=1, min_px=min_px, progress=False,
                            indices=range(0, len(ds), stride))
    res = evaluate(ds, rows, min_px=min_px)
    per = {oid: (v["n_correct"], v["n_gt"]) for oid, v in res.per_object.items()}
    return name, res.accuracy, res.n_correct, res.n_gt, res.instances_per_s, per


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--split", default="test")
    ap.add_argument("--method", default="ransac", choices=["ransac", "fgr", "super4pcs"])
    ap.add_argument("--icp", action="store_true")
    ap.add_argument("--preset", default="default")
    ap.add_argument("--variant", action="append", default=[], help="NAME:field=value,... (repeatable)")
    ap.add_argument("--stride", type=int, default=5)
    ap.add_argument("--min-px", type=int, default=MIN_VISIBLE_PX)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--csv", default=None)
    from sixdpose.artifacts.results import add_result_arguments, save_from_args, script_command

    add_result_arguments(ap, None, Path(__file__).resolve().parents[1] / "results", "tune_<method>[_icp]")
    args = ap.parse_args(argv)
    if args.result_name is None:
        args.result_name = f"tune_{args.method}" + ("_icp" if args.icp else "")
    data = args.data
    if data is None:
        from sixdpose.generation import ensure_dataset

        data = ensure_dataset(Path(__file__).resolve().parents[1] / "data" / "val", profile="val")
    variants = [_parse_variant(v) for v in (args.variant or ["base:"])]
    jobs = [
        (str(data), args.split, args.method, args.icp, args.preset, n, kw, args.stride, args.min_px)
        for n, kw in variants
    ]
    label = args.method + ("+icp" if args.icp else "")
    out = []
    with mp.get_context("spawn").Pool(max(1, min(args.jobs, len(jobs)))) as pool:
        for name, acc, nc, ng, ips, per in pool.imap(_run, jobs):
            worst = sorted(per.items(), key=lambda kv: kv[1][0] / max(kv[1][1], 1))[:4]
            print(f"{label:14s} {name:28s} ADD(-S) {acc:6.2f}% ({nc}/{ng})  {ips:6.2f} inst/s   worst: "
                  + " ".join(f"{o}:{c}/{n}" for o, (c, n) in worst), flush=True)
            out.append((label, name, dict(dict(variants)[name]), acc, nc, ng, ips))
    if args.csv:
        from sixdpose.artifacts.tables import write_table

        cols = ["method", "variant", "overrides", "add_s_accuracy", "n_correct", "n_gt", "instances_per_s"]
        write_table([dict(zip(cols, o, strict=True)) for o in out], cols, args.csv)
    cols = ["method", "variant", "overrides", "add_s_accuracy", "n_correct", "n_gt", "instances_per_s"]
    save_from_args(args, [dict(zip(cols, o, strict=True)) for o in out], command=script_command(__file__, argv),
                   units={"add_s_accuracy": "%", "n_correct": "GT instances", "n_gt": "GT instances",
                          "instances_per_s": "instances/s"},
                   description=f"{label} sweep on every {args.stride}-th image of {Path(str(data)).name} (GT masks, "
                               f">= {args.min_px} px; {args.jobs} one-thread processes at a time, so instances/s "
                               f"are slower than a quiet core)",
                   config={"data": str(data), "split": args.split, "preset": args.preset, "stride": args.stride,
                           "min_px": args.min_px, "jobs": args.jobs})
    return 0


if __name__ == "__main__":
    sys.exit(main())
