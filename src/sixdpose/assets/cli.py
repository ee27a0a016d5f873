"""``sixdpose fetch-ycb``: command line of the asset stage."""

from __future__ import annotations

from .. import options as O


def register(sub) -> None:
    """Add the ``fetch-ycb`` subcommand."""
    from .fetch import DEFAULT_BASE_URL

    p = sub.add_parser("fetch-ycb", help="download the official YCB google_16k models",
                       description="Download <name>_google_16k.tgz per object into DIR (official layout) "
                       "and write DIR/objects.csv. Needs internet access.")
    O.add(p, "--out")
    p.add_argument("--objects", nargs="+", default=None, help="object names (default: all 46)")
    p.add_argument("--base-url", default=DEFAULT_BASE_URL, help="archive location (default: the official YCB site)")
    p.add_argument("--overwrite", action="store_true", help="download again objects already present")
    p.add_argument("--timeout", type=O.Float(0.0, 3600.0, lo_open=True), default=60.0,
                   help="network timeout in seconds")
    O.add(p, "--no-progress")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from .fetch import fetch_ycb

    got = fetch_ycb(args.out, args.objects, base_url=args.base_url, timeout=args.timeout, overwrite=args.overwrite,
                    progress=not args.no_progress)
    print(f"fetched {len(got)} object(s) into {args.out}")
    return 0
