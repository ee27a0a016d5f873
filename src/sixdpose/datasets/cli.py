"""``sixdpose export-bop``: write a synthetic dataset in the BOP layout (readable by bop_toolkit)."""

from __future__ import annotations


def register(sub) -> None:
    """Add the ``export-bop`` subcommand."""
    p = sub.add_parser("export-bop", help="export a synthetic dataset to the BOP format",
                       description="Write DIR (synthetic layout) as a BOP dataset: models in mm, 16-bit depth, mask_visib.")
    p.add_argument("--data", required=True, help="synthetic dataset directory")
    p.add_argument("--out", required=True, help="BOP dataset root to create")
    p.add_argument("--split", default="test", help="split folder name to write (default test)")
    p.add_argument("--depth-scale", type=float, default=0.1, help="BOP depth unit in mm (default 0.1)")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from .readers import open_dataset
    from .bop import export_bop

    ds = open_dataset(args.data)
    out = export_bop(ds, args.out, split=args.split, depth_scale=args.depth_scale)
    print(f"exported {len(ds)} images to {out}")
    return 0
