"""``sixdpose register``: run a hybrid method over a dataset split, write BOP-format results."""

from __future__ import annotations

import argparse
import logging


def _param(s: str) -> tuple[str, object]:
    if "=" not in s:
        raise argparse.ArgumentTypeError(f"--set expects NAME=VALUE, got {s!r}")
    k, v = s.split("=", 1)
    import yaml

    return k.strip(), yaml.safe_load(v)


def register(sub) -> None:
    """Add the ``register`` subcommand."""
    p = sub.add_parser("register", help="hybrid pose estimation (RANSAC / FGR / Super4PCS [+ ICP])",
                       description="Register every instance of a dataset split; write a BOP results CSV.")
    p.add_argument("--data", required=True, help="dataset directory (synthetic layout or BOP root)")
    p.add_argument("--method", required=True, choices=["ransac", "fgr", "super4pcs"])
    p.add_argument("--icp", action="store_true", help="refine with ICP (point-to-plane by default)")
    p.add_argument("--masks", default="gt", help="'gt' or a directory of predicted masks (<scene>_<im>.npz)")
    p.add_argument("--split", default="test", help="BOP split (ignored for the synthetic layout)")
    p.add_argument("--out", required=True, help="results CSV to write")
    p.add_argument("--preset", default="default", help="parameter preset: default | paper")
    p.add_argument("--set", dest="overrides", action="append", type=_param, default=[], metavar="NAME=VALUE",
                   help="override one preset field, e.g. --set s4pcs_samples=300 (repeatable)")
    p.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    p.add_argument("--limit", type=int, default=None, help="only the first N images")
    p.add_argument("--stride", type=int, default=1, help="only every N-th image (a fixed subset spread over the scenes)")
    p.add_argument("--min-px", type=int, default=0, help="with GT masks, skip instances with fewer visible pixels")
    p.add_argument("--min-score", type=float, default=0.5,
                   help="with predicted masks, skip detections whose score is below this (default 0.5)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from ..cli import UserError
    from .presets import get_preset
    from .runner import run_registration, write_results

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        cfg = get_preset(args.preset, **dict(args.overrides))
    except (ValueError, TypeError) as e:
        raise UserError(str(e)) from None
    if args.workers < 1:
        raise UserError("--workers must be >= 1")
    if args.stride < 1:
        raise UserError("--stride must be >= 1")
    indices = None
    if args.stride > 1:
        from ..datasets.base import open_dataset

        try:
            indices = range(0, len(open_dataset(args.data, split=args.split)), args.stride)
        except Exception:  # an unreadable dataset is reported by run_registration below
            indices = None
    failures: list = []
    rows = run_registration(args.data, args.method, icp=args.icp, masks=args.masks, split=args.split, cfg=cfg,
                            workers=args.workers, limit=args.limit, min_px=args.min_px,
                            min_score=args.min_score, progress=not args.no_progress, indices=indices,
                            failures=failures)
    write_results(rows, args.out)
    n_bad = sum(1 for r in rows if r.reason)
    msg = f"wrote {len(rows)} estimates ({n_bad} with score 0) to {args.out}"
    if failures:
        import csv
        from pathlib import Path

        out = Path(args.out)
        fpath = out.with_name(out.stem + "_skipped_images.csv")
        with open(fpath, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["scene_id", "im_id", "reason"])
            w.writerows(failures)
        msg += f"; {len(failures)} unreadable image(s) skipped, listed in {fpath}"
    print(msg)
    return 0
