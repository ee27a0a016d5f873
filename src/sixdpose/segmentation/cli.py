"""Subcommands of the segmentation stage: ``train-seg``, ``segment``, ``eval-seg``.

Multi-GPU training: ``torchrun --nproc_per_node N -m sixdpose.cli train-seg ...`` (or the
``sixdpose`` script under ``torchrun --no-python``); each process uses its ``LOCAL_RANK`` GPU.
"""

from __future__ import annotations

from ..config import add_set_option, parse_overrides
from .config import PROFILES
from ..logs import setup_logging


def _cmd_train(args) -> int:
    from .train import train

    setup_logging(args.verbose)
    overrides = parse_overrides(args.overrides)
    for name in ("epochs", "batch_size", "lr", "seed", "num_workers", "max_steps_per_epoch", "val_fraction"):
        v = vars(args)[name]
        if v is not None:
            overrides[name] = v
    if args.threads is not None:
        overrides["num_threads"] = args.threads
    if args.train_split is not None:
        overrides["train_split"] = args.train_split
    if args.test_split is not None:
        overrides["test_split"] = args.test_split
    if args.no_amp:
        overrides["amp"] = False
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
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    r = segment(
        args.data,
        args.ckpt,
        args.out,
        split=args.split,
        subset=args.subset,
        batch_size=args.batch_size,
        device=args.device,
        score_thresh=args.score_thresh,
        num_workers=args.num_workers,
        progress=not args.no_progress,
    )
    print(
        f"segmented {r['images']} image(s), {r['detections']} detection(s), "
        f"{r['images_per_s']:.2f} images/s; predictions in {r['pred_dir']}"
    )
    return 0


def _cmd_eval(args) -> int:
    from .evaluate import evaluate

    setup_logging(args.verbose)
    m = evaluate(args.data, args.pred, args.figures, tag=args.tag)
    mk, bx = m["overall"]["mask"], m["overall"]["box"]
    print(
        f"{m['n_images']} image(s), {m['n_gt']} instance(s): mask AP {mk['AP']:.3f} AP50 {mk['AP50']:.3f} "
        f"AP75 {mk['AP75']:.3f} | box AP {bx['AP']:.3f} AP50 {bx['AP50']:.3f} AP75 {bx['AP75']:.3f}"
    )
    for f in m.get("files", []):
        print(f"wrote {f}")
    return 0


def register(subparsers) -> None:
    """Add ``train-seg``, ``segment`` and ``eval-seg`` to the ``sixdpose`` parser."""
    p = subparsers.add_parser(
        "train-seg",
        help="train Mask R-CNN instance segmentation (paper IV-A)",
        description="Train Mask R-CNN (ResNet-FPN) on a dataset's target objects. Profiles: smoke (CPU, "
        "minutes) and paper (section IV-A). Multi-GPU: run under torchrun.",
    )
    p.add_argument("--data", required=True, help="dataset directory (synthetic layout or BOP root)")
    p.add_argument("--out", required=True, help="run directory (config, split, checkpoints, metrics)")
    p.add_argument("--profile", choices=tuple(PROFILES), default=None,
                   help="named config: smoke (CI), cpu (2-core CPU, about 30 min on the train split), paper "
                        "(section IV-A, GPU); default smoke; on --resume: the run's")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its last completed epoch")
    p.add_argument("--epochs", type=int, help="override the number of epochs (allowed on --resume to extend a run)")
    p.add_argument("--batch-size", dest="batch_size", type=int, help="images per step and process")
    p.add_argument("--lr", type=float, help="initial learning rate")
    p.add_argument("--seed", type=int, help="seed of split, initialisation and augmentation")
    p.add_argument("--val-fraction", dest="val_fraction", type=float, help="held-out share of a synthetic dataset")
    p.add_argument("--max-steps-per-epoch", dest="max_steps_per_epoch", type=int, help="cap steps per epoch (0: none)")
    p.add_argument("--train-split", dest="train_split", help="BOP split used for training (default train)")
    p.add_argument("--test-split", dest="test_split", help="BOP split used for testing (default test)")
    p.add_argument("--num-workers", dest="num_workers", type=int, help="data-loading workers")
    p.add_argument("--threads", type=int, help="torch CPU threads per process")
    p.add_argument("--device", default=None, help="cpu, cuda or auto (default: GPU when present)")
    p.add_argument("--no-amp", action="store_true", help="disable mixed precision on GPU")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("-v", "--verbose", action="store_true", help="log every skipped instance and epoch")
    add_set_option(p)
    p.set_defaults(func=_train_entry)

    p = subparsers.add_parser(
        "segment",
        help="predict instance masks with a trained Mask R-CNN run",
        description="Write PRED_DIR/<scene_id>_<im_id>.npz (masks (N,H,W) bool, labels (N,) obj ids, "
        "scores (N,) float32) per image, and PRED_DIR/coco_results.json.",
    )
    p.add_argument("--data", required=True, help="dataset directory")
    p.add_argument("--ckpt", required=True, help="run directory of train-seg (or a checkpoint file)")
    p.add_argument("--out", required=True, help="prediction directory")
    p.add_argument("--split", default="test", help="BOP split to segment (default test; ignored for synthetic data)")
    p.add_argument("--subset", choices=("all", "train", "test"), default="all", help="all images, or the run's train/test images")
    p.add_argument("--batch-size", dest="batch_size", type=int, default=4, help="images per forward pass")
    p.add_argument("--score-thresh", dest="score_thresh", type=float, default=None, help="minimum detection score (default: the run's, 0.05)")
    p.add_argument("--num-workers", dest="num_workers", type=int, default=0, help="image-loading workers")
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads")
    p.add_argument("--device", default=None, help="cpu, cuda or auto")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("-v", "--verbose", action="store_true")
    p.set_defaults(func=_cmd_segment)

    p = subparsers.add_parser(
        "eval-seg",
        help="COCO mask/box AP of segment's predictions",
        description="Evaluate PRED_DIR against the dataset's ground truth with pycocotools; writes "
        "seg_ap<TAG>.csv and .tex to --figures.",
    )
    p.add_argument("--data", required=True, help="dataset directory that was segmented")
    p.add_argument("--pred", required=True, help="prediction directory of `sixdpose segment`")
    p.add_argument("--figures", default="figures", help="output directory of the tables (default figures/)")
    p.add_argument("--tag", default="", help="file name suffix, e.g. _smoke")
    p.add_argument("-v", "--verbose", action="store_true")
    p.set_defaults(func=_cmd_eval)


def _train_entry(args) -> int:
    if args.profile is None and not args.resume:
        args.profile = "smoke"
    return _cmd_train(args)

