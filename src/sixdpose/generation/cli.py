"""``sixdpose generate``: the synthetic dataset generator's command line."""

from __future__ import annotations

import argparse
import json
import sys

from ..config import add_set_option, parse_overrides
from .config import PROFILES


def _nonneg_int(s: str) -> int:
    try:
        return int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {s!r}") from None


def register(sub) -> None:
    """Add the ``generate`` subcommand."""
    p = sub.add_parser(
        "generate",
        help="generate the synthetic dataset (Drake physics + rendering, paper section III)",
        description="Drop YCB objects on a table, simulate, render RGB-D views along a camera arc and write "
        "the paper's layout. Re-running with the same arguments resumes an interrupted run.",
    )
    p.add_argument("--out", required=True, help="output dataset directory")
    p.add_argument("--scenes", type=_nonneg_int, default=None, help="number of scenes (default: the profile's)")
    p.add_argument("--views", type=_nonneg_int, default=None, help="views per scene (default 20)")
    p.add_argument("--seed", type=_nonneg_int, default=None, help="random seed (default: the profile's; 0 for smoke, demo, paper)")
    p.add_argument("--profile", default="demo", choices=sorted(PROFILES), help="named config profile (default demo)")
    p.add_argument("--workers", type=_nonneg_int, default=1, help="parallel scene workers (default 1)")
    p.add_argument("--assets", default=None, help="YCB asset directory (default: $SIXDPOSE_YCB)")
    p.add_argument("--executor", default="local", choices=["local", "ray"], help="local processes or a Ray cluster")
    p.add_argument("--address", default=None, help="Ray cluster address (default: start a local instance)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_set_option(p)
    p.set_defaults(func=_run)


def _run(args) -> int:
    from .config import profile
    from .runner import generate

    overrides = parse_overrides(args.overrides)
    overrides.update({k: v for k, v in (("scenes", args.scenes), ("views", args.views), ("seed", args.seed)) if v is not None})
    cfg = profile(args.profile, **overrides)
    res = generate(args.out, cfg, workers=args.workers, assets=args.assets, executor=args.executor,
                   address=args.address, progress=not args.no_progress)
    summary = {k: v for k, v in res.items() if k != "manifest"}
    print(json.dumps(summary, indent=None, default=float))
    if res["scenes_failed"]:
        print(f"sixdpose generate: {len(res['scenes_failed'])} scene(s) failed (listed in manifest.json); "
              "run the same command again to retry them", file=sys.stderr)
        return 1
    return 0
