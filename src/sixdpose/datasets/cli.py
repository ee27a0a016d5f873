"""``sixdpose export-bop``: write a synthetic dataset in the BOP layout (readable by bop_toolkit)."""

from __future__ import annotations

from .. import options as O


def register(sub) -> None:
    """Add the ``export-bop`` subcommand."""
    p = sub.add_parser(
        "export-bop",
        help="export a synthetic dataset to the BOP format",
        description="Write DIR (synthetic layout) as a BOP dataset: models in mm, 16-bit depth, mask_visib.",
    )
    O.add(p, "--data", help="synthetic dataset directory")
    O.add(p, "--out", help="BOP dataset root to create")
    O.add(p, "--split", help="split folder name to write (default test)")
    p.add_argument("--depth-scale", type=O.Float(0.0, 100.0, lo_open=True), default=0.1,
                   help="BOP depth unit in mm (default 0.1)")
    O.add(p, "--no-progress")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from ..fileio import claim_output_dir
    from .bop import export_bop
    from .readers import open_dataset

    claim_output_dir(args.out, "export-bop", create=False)  # refuse an unusable --out before reading the dataset
    ds = open_dataset(args.data)
    out = export_bop(ds, args.out, split=args.split, depth_scale=args.depth_scale, progress=not args.no_progress)
    print(f"exported {len(ds)} images to {out}")
    return 0
