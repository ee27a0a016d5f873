"""Subcommands of the segmentation stage: ``train-seg``, ``segment``, ``eval-seg``.

Multi-GPU training: ``torchrun --nproc_per_node N -m sixdpose.cli train-seg ...`` (or the
``sixdpose`` script under ``torchrun --no-python``); each process uses its ``LOCAL_RANK`` GPU.
"""

from __future__ import annotations

from .. import options as O
from ..config import add_set_option, parse_overrides
from ..logs import setup_logging
from .config import PROFILES, SegConfig


def _cmd_train(args) -> int:
    from .train import train

    setup_logging(args.verbose)
    overrides = parse_overrides(args.overrides)
    for name in ("epochs", "batch_size", "lr", "seed", "max_steps_per_epoch", "val_fraction"):
        v = vars(args)[name]
        if v is not None:
            overrides[name] = v
    if args.workers is not None:
        overrides["num_workers"] = args.workers
    if args.threads is not None:
        overrides["num_threads"] = args.threads
    if args.train_split is not None:
        overrides["train_split"] = args.train_split
    if args.test_split is not None:
        overrides["test_split"] = args.test_split
    if args.no_amp:
        overrides["amp"] = False
    if not args.resume:  # a bad --set fails here, before the run directory exists
        from .config import profile_config

        profile_config(args.profile, **overrides)
    summary = train(
        args.data,
        args.out,
        profile=args.profile,
        resume=args.resume,
        device=args.device,
        progress=not args.no_progress,
        **overrides,
    )
    import os

    if int(os.environ.get("RANK", "0")) == 0:
        print(
            f"trained {summary['steps']} step(s), epochs {summary['start_epoch']}->{summary['epochs']}, "
            f"loss {summary['first_loss']:.4f} -> {summary['last_loss']:.4f}, backbone init {summary['init']}, "
            f"{summary['seconds']:.0f} s; run in {summary['run_dir']}"
        )
    return 0


def _cmd_segment(args) -> int:
    from .infer import segment

    setup_logging(args.verbose)
    O.set_threads(args.threads)
    r = segment(
        args.data,
        args.ckpt,
        args.out,
        split=args.split,
        subset=args.subset,
        batch_size=args.batch_size,
        device=args.device,
        score_thresh=args.score_thresh,
        num_workers=args.workers,
        progress=not args.no_progress,
        overrides=parse_overrides(args.overrides),
    )
    print(
        f"segmented {r['images']} image(s), {r['detections']} detection(s), "
        f"{r['images_per_s']:.2f} images/s; predictions in {r['pred_dir']}"
    )
    return 0


def _cmd_eval(args) -> int:
    from ..fileio import check_output_location
    from .evaluate import evaluate

    setup_logging(args.verbose)
    check_output_location(args.figures)  # a file or an unwritable place fails before any work
    m = evaluate(args.data, args.masks, args.figures, tag=args.tag, progress=not args.no_progress)
    mk, bx = m["overall"]["mask"], m["overall"]["box"]
    print(
        f"{m['n_images']} image(s), {m['n_gt']} instance(s): mask AP {mk['AP']:.3f} AP50 {mk['AP50']:.3f} "
        f"AP75 {mk['AP75']:.3f} | box AP {bx['AP']:.3f} AP50 {bx['AP50']:.3f} AP75 {bx['AP75']:.3f}"
    )
    for f in m.get("files", []):
        print(f"wrote {f}")
    return 0


def _runtime_args(p, *, amp: bool = False, **verbose) -> None:
    """The compute options train-seg and segment share (``--no-amp`` when ``amp``), then ``--set``;
    ``verbose`` may set the ``help`` of ``--verbose``."""
    O.add_many(p, "--workers", "--threads", "--device")
    if amp:
        p.add_argument("--no-amp", action="store_true", help="disable mixed precision on GPU")
    O.add(p, "--no-progress")
    O.add(p, "--verbose", **verbose)
    add_set_option(p)


def _train_args(p) -> None:
    O.add(p, "--data")
    O.add(p, "--out", help="run directory (config, split, checkpoints, metrics)")
    O.add_profile(p, PROFILES, help="named config: smoke (CI), cpu (2-core CPU, about 30 min on the train split), "
                  "paper (section IV-A, GPU); default smoke; on --resume: the run's")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last completed epoch")
    O.add(p, "--epochs", help="override the number of epochs (allowed on --resume to extend a run)")
    O.add(p, "--batch-size", help="images per step and process")
    p.add_argument("--lr", type=O.field_type(SegConfig, "lr"), help="initial learning rate")
    O.add(p, "--seed", help="seed of split, initialisation and augmentation")
    p.add_argument("--val-fraction", dest="val_fraction", type=O.field_type(SegConfig, "val_fraction"),
                   help="held-out share of a synthetic dataset")
    p.add_argument("--max-steps-per-epoch", dest="max_steps_per_epoch",
                   type=O.field_type(SegConfig, "max_steps_per_epoch"),
                   help="cap steps per epoch (0: none)")
    p.add_argument("--train-split", dest="train_split", type=O.Name(),
                   help="BOP split used for training (default train)")
    p.add_argument("--test-split", dest="test_split", type=O.Name(), help="BOP split used for testing (default test)")
    _runtime_args(p, amp=True, help="log every skipped instance and epoch")


def _segment_args(p) -> None:
    O.add(p, "--data")
    O.add(p, "--seg")
    O.add(p, "--out", help="prediction directory")
    O.add(p, "--split", help="BOP split to segment (default test; ignored for synthetic data)")
    p.add_argument("--subset", choices=("all", "train", "test"), default="all",
                   help="all images, or the run's train/test images")
    O.add(p, "--batch-size")
    O.add(p, "--score-thresh")
    _runtime_args(p)


def _eval_args(p) -> None:
    O.add(p, "--data", help="dataset directory that was segmented")
    O.add(p, "--masks", required=True, help="prediction directory of `sixdpose segment`")
    p.add_argument("--figures", default="figures", help="output directory of the tables (default figures/)")
    p.add_argument("--tag", default="", type=O.Name(allow_empty=True), help="file name suffix, e.g. _smoke")
    O.add(p, "--no-progress")
    O.add(p, "--verbose")


def register(subparsers) -> None:
    """Add ``train-seg``, ``segment`` and ``eval-seg`` to the ``sixdpose`` parser."""
    commands = (  # name, help, description, options, handler
        ("train-seg", "train Mask R-CNN instance segmentation (paper IV-A)",
         "Train Mask R-CNN (ResNet-FPN; --set backbone=mobilenet_v3_large for a lighter one) on a dataset's target "
         "objects. Profiles: smoke (CPU, minutes) and paper (section IV-A). Multi-GPU: run under torchrun.",
         _train_args, _train_entry),
        ("segment", "predict instance masks with a trained Mask R-CNN run",
         "Write PRED_DIR/<scene_id>_<im_id>.npz (masks (N,H,W) bool, labels (N,) obj ids, scores (N,) float32) "
         "per image, and PRED_DIR/coco_results.json.", _segment_args, _cmd_segment),
        ("eval-seg", "COCO mask/box AP of segment's predictions",
         "Evaluate PRED_DIR against the dataset's ground truth with pycocotools; writes seg_ap<TAG>.csv and .tex "
         "to --figures.", _eval_args, _cmd_eval),
    )
    for name, summary, description, add_options, handler in commands:
        p = subparsers.add_parser(name, help=summary, description=description)
        add_options(p)
        p.set_defaults(func=handler)


def _train_entry(args) -> int:
    if args.profile is None and not args.resume:
        args.profile = "smoke"
    return _cmd_train(args)

