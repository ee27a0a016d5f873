"""``sixdpose register``: run a hybrid method over a dataset split, write BOP-format results."""

from __future__ import annotations

import logging

from .. import options as O
from ..config import add_set_option, parse_overrides
from ..registry import HYBRID_ALGORITHMS
from .presets import PRESETS


def register(sub) -> None:
    """Add the ``register`` subcommand."""
    p = sub.add_parser("register", help="hybrid pose estimation (RANSAC / FGR / Super4PCS [+ ICP])",
                       description="Register every instance of a dataset split; write a BOP results CSV and, "
                                   "beside it, <out>.config.yml (the parameters used).")
    O.add(p, "--data")
    p.add_argument("--method", required=True, choices=list(HYBRID_ALGORITHMS))
    p.add_argument("--icp", action="store_true", help="refine with ICP (point-to-plane by default)")
    O.add(p, "--masks", help="'gt' or a directory of predicted masks (<scene>_<im>.npz)")
    O.add(p, "--split")
    O.add(p, "--out", help="results CSV to write")
    O.add_profile(p, PRESETS, help="parameter preset (sixdpose.registration.presets; default: default)")
    add_set_option(p)
    O.add(p, "--seed", help="random seed (default: the preset's, 0); each instance's seed is derived from it and "
                            "its ids: the same seed gives the same estimates with any --workers (in <out>.config.yml)")
    O.add(p, "--workers")
    O.add(p, "--limit")
    p.add_argument("--stride", type=O.Int(1, 1_000_000), default=1,
                   help="only every N-th image (a fixed subset spread over the scenes)")
    O.add(p, "--min-px")
    O.add(p, "--verify")
    O.add(
        p,
        "--score-thresh",
        help="with predicted masks, skip detections whose score is below this (default %(default)s)",
    )
    O.add(p, "--no-progress")
    p.add_argument("--no-resume", dest="resume", action="store_false",
                   help="ignore the journal <out>.journal of a stopped run with the same arguments and start over "
                        "(by default the images it holds are not registered again)")
    p.set_defaults(func=_run)


def run_fingerprint(args, cfg, ds) -> dict:
    """What names a ``register`` run for its journal (:mod:`sixdpose.artifacts.journal`): the method, the
    settings, the dataset, the masks (with a hash of a predicted-mask directory's ``meta.json``, which a new
    segmentation rewrites) and the images."""
    import hashlib
    from pathlib import Path

    meta = Path(args.masks) / "meta.json" if args.masks != "gt" else None
    return {"command": "register", "method": args.method, "icp": bool(args.icp), "config": cfg.to_dict(),
            "data": str(Path(ds.location).resolve()), "split": args.split, "n_images": len(ds),
            "masks": str(args.masks),
            "masks_meta_sha256": hashlib.sha256(meta.read_bytes()).hexdigest() if meta and meta.is_file() else None,
            "limit": args.limit or None, "stride": args.stride, "min_px": args.min_px,
            "score_thresh": args.score_thresh}


def _run(args) -> int:
    from pathlib import Path

    from ..artifacts.journal import ImageJournal, journal_path
    from ..artifacts.poses import RESULTS_HEADER, write_results, write_results_config
    from ..artifacts.tables import write_table
    from ..datasets.readers import open_dataset
    from ..fileio import claim_output_file
    from .presets import get_preset, verify_by_default
    from .runner import run_registration

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    overrides = parse_overrides(args.overrides)
    if args.seed is not None:
        overrides["seed"] = args.seed
    if args.verify is not None:  # --verify / --no-verify win over --set verify=...
        overrides["verify"] = args.verify
    elif "verify" not in overrides:
        overrides["verify"] = verify_by_default(args.profile)
    cfg = get_preset(args.profile, **overrides)
    out = Path(args.out)
    claim_output_file(out, RESULTS_HEADER)  # refuse a foreign file before any work
    ds = open_dataset(args.data, split=args.split)
    indices = range(0, len(ds), args.stride) if args.stride > 1 else None
    failures: list = []
    timing: dict = {}
    # a stopped run leaves <out>.journal; the same command resumes from it (sixdpose.artifacts.journal)
    journal = ImageJournal(journal_path(out), run_fingerprint(args, cfg, ds), resume=args.resume)
    rows = run_registration(ds, args.method, icp=args.icp, masks=args.masks, cfg=cfg, workers=args.workers,
                            limit=args.limit or None, min_px=args.min_px, min_score=args.score_thresh,
                            progress=not args.no_progress, indices=indices, failures=failures, timing=timing,
                            journal=journal)
    write_results(rows, out)
    # the config, and the objects' onboarding seconds that the CSV's per-image times leave out
    write_results_config(out, {**cfg.to_dict(), "onboarding_s": round(timing.get("onboarding_s", 0.0), 3)})
    journal.remove()  # its rows are in the CSV now
    n_bad = sum(1 for r in rows if r.reason)
    msg = f"wrote {len(rows)} estimates ({n_bad} with score 0) to {out}"
    if timing.get("onboarding_s"):
        msg += f" (objects' onboarding {timing['onboarding_s']:.1f} s, not in the per-image times)"
    if failures:
        fpath = out.with_name(out.stem + "_skipped_images.csv")
        write_table(
            [dict(zip(("scene_id", "im_id", "reason"), f, strict=True)) for f in failures],
            ["scene_id", "im_id", "reason"],
            fpath,
        )
        msg += f"; {len(failures)} unreadable image(s) skipped, listed in {fpath}"
    print(msg)
    return 0
