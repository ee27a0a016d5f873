"""``sixdpose generate``: the synthetic dataset generator's command line."""

from __future__ import annotations

import json
import sys

from .. import options as O
from ..config import add_set_option, from_profile, parse_overrides
from .config import PROFILES, GenerationConfig


def _names(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def register(sub) -> None:
    """Add the ``generate`` subcommand."""
    p = sub.add_parser(
        "generate",
        help="generate the synthetic dataset (Drake physics + rendering, paper section III)",
        description="Drop YCB objects on a table, simulate, render RGB-D views along a camera arc and write "
        "the paper's layout. Re-running with the same arguments resumes an interrupted run. Targets are the "
        "paper's 18 YCB objects unless --targets, --assets-bop or a profile (ycbv) says otherwise.",
        epilog="Your own objects: --targets 006_mustard_bottle,011_banana (YCB names; obj_ids = list positions); "
        "--assets-bop DIR/models (a BOP dataset's models as targets: ground truth in its model frames and "
        "obj_ids; --targets 1,5 or obj_000005 picks some); --camera DIR/camera.json (that camera's K and size); "
        "--profile ycbv (YCB-Video: 19 textured ycbv models, YCB noise, YCB-Video camera, kinect depth, BOP copy "
        "in OUT/bop). Everything lands in the dataset's config.yml.",
    )
    O.add(p, "--out", help="output dataset directory")
    p.add_argument("--scenes", type=O.field_type(GenerationConfig, "scenes"), default=None,
                   help="number of scenes (default: the profile's)")
    p.add_argument("--views", type=O.field_type(GenerationConfig, "views"), default=None,
                   help="views per scene (default 20)")
    O.add(p, "--seed", help="random seed (default: the profile's; 0 for smoke, demo, paper)")
    O.add_profile(p, sorted(PROFILES), help="named config profile (default demo)")
    O.add(p, "--workers")
    p.add_argument("--assets", default=None, help="YCB asset directory (default: $SIXDPOSE_YCB)")
    p.add_argument("--targets", default=None, metavar="A,B,...",
                   help="comma-separated target objects (sets target_objects): YCB names, or with --assets-bop "
                        "obj_NNNNNN / obj_ids (default: the paper's 18, or every BOP model)")
    p.add_argument("--noise", dest="noise_objects", default=None, metavar="A,B,...",
                   help="comma-separated YCB names of the noise pool (sets noise_objects; default: every YCB "
                        "object that is not a target)")
    p.add_argument("--assets-bop", dest="assets_bop", default=None, metavar="DIR/models",
                   help="use a BOP dataset's models (PLY, mm) as the targets (sets target_source=bop; default "
                        "directory for bop profiles: $SIXDPOSE_BOP_MODELS, then ../shared/data/ycbv_sample/models "
                        "for ycbv)")
    p.add_argument("--camera", default=None, metavar="JSON",
                   help="BOP camera.json or scene_camera.json: render with its intrinsics and image size "
                        "(sets camera.intrinsics, camera.width, camera.height)")
    p.add_argument("--cache", default=None, metavar="DIR",
                   help="cache of converted BOP models "
                        "(default $SIXDPOSE_CACHE/bop_models or ~/.cache/sixdpose/bop_models)")
    p.add_argument("--executor", default="local", choices=["local", "ray"], help="local processes or a Ray cluster")
    p.add_argument("--address", default=None, help="Ray cluster address (default: start a local instance)")
    O.add(p, "--no-progress")
    add_set_option(p)
    p.set_defaults(func=_run)


def _run(args) -> int:
    from .runner import generate

    overrides = parse_overrides(args.overrides)
    overrides.update({k: v for k, v in (("scenes", args.scenes), ("views", args.views), ("seed", args.seed))
                      if v is not None})
    if args.targets is not None:
        overrides["target_objects"] = _names(args.targets)
    if args.noise_objects is not None:
        overrides["noise_objects"] = _names(args.noise_objects)
    if args.assets_bop is not None:
        overrides["target_source"] = "bop"
    if args.camera is not None:
        from .config import camera_from_bop

        overrides.update(camera_from_bop(args.camera))
    cfg = from_profile(PROFILES, args.profile, overrides)  # --set key=null sets a field to null
    res = generate(args.out, cfg, workers=args.workers, assets=args.assets, executor=args.executor,
                   address=args.address, progress=not args.no_progress, assets_bop=args.assets_bop,
                   cache_dir=args.cache)
    summary = {k: v for k, v in res.items() if k != "manifest"}
    print(json.dumps(summary, indent=None, default=float))
    if res["scenes_failed"]:
        print(f"sixdpose generate: {len(res['scenes_failed'])} scene(s) failed (listed in manifest.json); "
              "run the same command again to retry them", file=sys.stderr)
        return 1
    return 0
