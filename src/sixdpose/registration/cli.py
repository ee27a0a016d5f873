"""``sixdpose register``: run a hybrid method over a dataset split, write BOP-format results."""

from __future__ import annotations

import logging

from ..config import add_set_option, parse_overrides


def register(sub) -> None:
    """Add the ``register`` subcommand."""
    p = sub.add_parser("register", help="hybrid pose estimation (RANSAC / FGR / Super4PCS [+ ICP])",
                       description="Register every instance of a dataset split; write a BOP results CSV and, "
                                   "beside it, <out>.config.yml (the parameters used).")
    p.add_argument("--data", required=True, help="dataset directory (synthetic layout or BOP root)")
    p.add_argument("--method", required=True, choices=["ransac", "fgr", "super4pcs"])
    p.add_argument("--icp", action="store_true", help="refine with ICP (point-to-plane by default)")
    p.add_argument("--masks", default="gt", help="'gt' or a directory of predicted masks (<scene>_<im>.npz)")
    p.add_argument("--split", default="test", help="BOP split (ignored for the synthetic layout)")
    p.add_argument("--out", required=True, help="results CSV to write")
    p.add_argument("--preset", default="default", help="parameter preset: default | paper")
    add_set_option(p)
    p.add_argument("--seed", type=int, default=None,
                   help="random seed (default: the preset's, 0); each instance's seed is derived from it and "
                        "its ids: the same seed gives the same estimates with any --workers (in <out>.config.yml)")
    p.add_argument("--workers", type=int, default=2, help="processes (default 2)")
    p.add_argument("--limit", type=int, default=None, help="only the first N images")
    p.add_argument("--stride", type=int, default=1, help="only every N-th image (a fixed subset spread over the scenes)")
    p.add_argument("--min-px", type=int, default=0, help="with GT masks, skip instances with fewer visible pixels")
    p.add_argument("--min-score", type=float, default=0.5,
                   help="with predicted masks, skip detections whose score is below this (default 0.5)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from pathlib import Path

    from ..artifacts.poses import RESULTS_HEADER, write_results
    from ..artifacts.tables import write_table
    from ..cli import UserError
    from ..datasets.base import open_dataset
    from ..fileio import claim_output_file
    from .presets import get_preset
    from .runner import run_registration

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    overrides = parse_overrides(args.overrides)
    if args.seed is not None:
        if args.seed < 0:
            raise UserError("--seed must be >= 0")
        overrides["seed"] = args.seed
    cfg = get_preset(args.preset, **overrides)
    if args.workers < 1:
        raise UserError("--workers must be >= 1")
    if args.stride < 1:
        raise UserError("--stride must be >= 1")
    out = Path(args.out)
    claim_output_file(out, RESULTS_HEADER)  # refuse a foreign file before any work
    ds = open_dataset(args.data, split=args.split)
    indices = range(0, len(ds), args.stride) if args.stride > 1 else None
    failures: list = []
    rows = run_registration(ds, args.method, icp=args.icp, masks=args.masks, cfg=cfg, workers=args.workers,
                            limit=args.limit, min_px=args.min_px, min_score=args.min_score,
                            progress=not args.no_progress, indices=indices, failures=failures)
    write_results(rows, out)
    cfg.save(out.with_name(out.stem + ".config.yml"))
    n_bad = sum(1 for r in rows if r.reason)
    msg = f"wrote {len(rows)} estimates ({n_bad} with score 0) to {out}"
    if failures:
        fpath = out.with_name(out.stem + "_skipped_images.csv")
        write_table([dict(zip(("scene_id", "im_id", "reason"), f)) for f in failures], ["scene_id", "im_id", "reason"], fpath)
        msg += f"; {len(failures)} unreadable image(s) skipped, listed in {fpath}"
    print(msg)
    return 0
