"""``sixdpose fetch-ycb``, ``sixdpose fetch-weights``: command line of the asset stage."""

from __future__ import annotations

from .. import options as O


def register(sub) -> None:
    """Add the ``fetch-ycb`` and ``fetch-weights`` subcommands."""
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
    _register_weights(sub)


def _register_weights(sub) -> None:
    from .weights import BACKBONES

    p = sub.add_parser(
        "fetch-weights", help="download torchvision's ImageNet backbone weights into the torch hub cache",
        description="Download the ImageNet weights the segmentation stage starts from (torchvision's "
        "IMAGENET1K_V1 of --backbone) into the torch hub cache ($TORCH_HOME/hub/checkpoints/<file>), where "
        "train-seg looks for them. Resumes an interrupted download (<file>.part, HTTP Range), checks the "
        "sha256 prefix of the file name (as torch.hub does), moves the file into place atomically; a file "
        "already there with a good checksum is kept. Offline: copy the file to that path, or give a mirror.")
    p.add_argument("--backbone", choices=BACKBONES, default="resnet50", help="the backbone (default: resnet50)")
    p.add_argument("--url", default=None, help="download from this URL instead of torchvision's (a mirror)")
    p.add_argument("--sha256", default=None, metavar="HEX",
                   help="expected sha256 (or a prefix of it, 8+ hex digits) instead of the file name's prefix")
    p.add_argument("--timeout", type=O.Float(0.0, 3600.0, lo_open=True), default=60.0,
                   help="network timeout in seconds")
    O.add(p, "--no-progress")
    p.set_defaults(func=_run_weights)


def _run_weights(args) -> int:
    from .weights import fetch_weights

    path, downloaded = fetch_weights(args.backbone, url=args.url, sha256=args.sha256, timeout=args.timeout,
                                     progress=not args.no_progress)
    print(f"{path}: {'downloaded, checksum ok' if downloaded else 'already present, checksum ok'}")
    return 0


def _run(args) -> int:
    from .fetch import fetch_ycb

    got = fetch_ycb(args.out, args.objects, base_url=args.base_url, timeout=args.timeout, overwrite=args.overwrite,
                    progress=not args.no_progress)
    print(f"fetched {len(got)} object(s) into {args.out}")
    return 0
